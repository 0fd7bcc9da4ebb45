"""Covar-GMM (Moulin-Frier, Nguyen and Oudeyer 2014): sample tasks where reward grows with time.

Each result becomes a point (task features, time, reward), where time is the result's position in
the current batch of ``fit_rate`` results, scaled to [0, 1). Every ``fit_rate`` results, Gaussian
mixtures with k = min..max components are fitted to that batch and the one with the lowest AIC is
kept. A component whose time-reward covariance is positive covers tasks whose reward rose during the
batch: the student is making progress there. A task comes from a component picked in proportion to
that covariance (its positive part, or with ``absolute_progress`` its absolute value, so forgetting
counts too), drawn from the component's Gaussian over the task coordinates and clipped to the box;
with probability ``random_task_ratio``, and for the first ``fit_rate`` tasks (the bootstrap), it is
uniform over the box. When no component shows progress, one is picked uniformly.

Against the teachDeepRL implementation (Portelas et al. 2019), whose defaults these are: tasks are
rescaled to [0, 1] per dimension before the fit (switchable; on a unit box it changes nothing), the
fit runs as a ``FitJob`` off the request path (so tasks drawn while it runs come from the previous
model), and every draw is addressed by the task's index instead of a global generator.

When it helps: like ALP-GMM, for a student that can learn only part of the space at a time; it sees
progress only where one batch of ``fit_rate`` results shows a trend, so it needs students whose
reward moves within a few hundred episodes.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from pydantic import Field

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms
from teacher_service.teachers.mixture import (
    MAX_FIT_RATE,
    MixtureFit,
    MixtureParams,
    MixtureSampler,
    MixtureTeacher,
)
from teacher_service.teachers.row_log import RowLog

REFIT_ROWS = 10_000
REFIT_BATCHES = 8
"""A fit only reads its own batch, but a restart may rerun a fit that was due before the crash:
the last REFIT_BATCHES batches, or REFIT_ROWS results if more, stay in memory for that."""


class CovarGmmParams(MixtureParams):
    fit_rate: int = Field(default=250, ge=4, le=MAX_FIT_RATE)
    """Results per batch: a mixture is fitted to each batch; the first ``fit_rate`` tasks are uniform."""
    absolute_progress: bool = False
    """Pick components by the absolute time-reward covariance (progress or forgetting) instead of its
    positive part (progress only, the reference's default)."""
    rescale_tasks: bool = True
    """Fit mixtures on tasks rescaled to [0, 1] per dimension."""


class CovarGmmTeacher(MixtureTeacher):
    """Time-reward covariance teacher over a Gaussian mixture (see the module docstring)."""

    kind = "covar-gmm"
    Params = CovarGmmParams
    params: CovarGmmParams
    extra_coordinates = 2

    def __init__(self, space: TaskSpace, seed: int, params: CovarGmmParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        self._log = RowLog(self._width, 2 * self.params.fit_rate)

    def _draw(self, first_index: int, count: int) -> list[Task]:
        dims = len(self.space)
        # Per task: uniform-or-mixture coin, component choice, d normal quantiles, d uniform coordinates.
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, 2 + 2 * dims)
        tasks = self.space.from_unit(uniforms[:, 2 + dims :])
        if self._sampler is not None:
            from_gmm = uniforms[:, 0] >= self.params.random_task_ratio
            features = self._sampler.draw(uniforms[:, 1], uniforms[:, 2 : 2 + dims])
            tasks = np.where(from_gmm[:, None], self._to_task_units(features), tasks)
        return [self.space.from_array(row) for row in tasks]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        rate = self.params.fit_rate
        time = (self._log.size % rate) / rate
        self._log.append(np.concatenate([self._to_features(self.space.to_array(result.task)), (time, result.reward)]))
        if self._log.size % rate:
            return None
        self._log.needed_from = max(0, self._log.size - max(REFIT_ROWS, REFIT_BATCHES * rate))
        self.fits_requested += 1
        return self.refit_job(self.fits_requested - 1)

    def _fit_points(self, start: int, stop: int) -> np.ndarray:
        """Task features, time in the batch and reward, copied for the fit job to own."""
        points: np.ndarray = self._log.view(start, stop).copy()
        return points

    def _prepare(self, fit: MixtureFit) -> MixtureSampler:
        """Components picked by their time-reward covariance: its positive part, or its size with
        ``absolute_progress``."""
        covariances = fit.covariances[:, -2, -1]
        progress = np.abs(covariances) if self.params.absolute_progress else np.clip(covariances, 0.0, None)
        return MixtureSampler.prepare(fit, progress, len(self.space))

    def _history_rows(self) -> RowLog:
        """One row per result: its task features, its time in its batch and its reward."""
        return self._log

    def _export(self) -> dict[str, Any]:
        return {"history_rows": self._log.size, "history_from": self._log.needed_from, **super()._export()}

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        self._log.load(history, int(state.get("history_from", 0)), int(state["history_rows"]))
        super()._import(state, history)

    def _to_features(self, tasks: np.ndarray) -> np.ndarray:
        return self.space.to_unit(tasks) if self.params.rescale_tasks else np.asarray(tasks, dtype=np.float64)

    def _to_task_units(self, features: np.ndarray) -> np.ndarray:
        return self.space.from_unit(features) if self.params.rescale_tasks else features

    def _describe(self) -> dict[str, Any]:
        rate = self.params.fit_rate
        return {
            "bootstrapping": self._sampler is None,
            "fits": self.fits_installed,
            "fits_requested": self.fits_requested,
            "last_fit_index": self._sampler.fit.index if self._sampler else None,
            "next_fit_at_results": (self.results_seen // rate + 1) * rate,
            "components": self._components(),
            "aic_by_components": (
                {str(k): aic for k, aic in self._sampler.fit.aic_by_components.items()} if self._sampler else {}
            ),
        }

    def _components(self) -> list[dict[str, Any]]:
        if self._sampler is None:
            return []
        fit = self._sampler.fit
        scale = (self.space.high - self.space.low) if self.params.rescale_tasks else np.ones(len(self.space))
        return [
            {
                "weight": float(weight),
                "mean": dict(zip(self.space.names, self._to_task_units(mean[:-2]).tolist(), strict=True)),
                "covariance": (covariance[:-2, :-2] * np.outer(scale, scale)).tolist(),
                "mean_time": float(mean[-2]),
                "mean_reward": float(mean[-1]),
                "time_reward_covariance": float(covariance[-2, -1]),
                "sampling_probability": float(probability),
            }
            for weight, mean, covariance, probability in zip(
                fit.weights, fit.means, fit.covariances, self._sampler.probabilities, strict=True
            )
        ]
