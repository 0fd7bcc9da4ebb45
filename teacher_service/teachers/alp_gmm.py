"""ALP-GMM (Portelas et al. 2019): sample tasks where the student's absolute learning progress is high.

For each result, ALP is the absolute reward difference to the nearest earlier task. Every
``fit_rate`` results, Gaussian mixtures with k = min..max components are fitted to the last
``fit_rate`` points of (task, ALP) and the one with the lowest AIC is kept. A task then comes from
a component picked in proportion to its mean ALP, or, with probability ``random_task_ratio``,
uniformly from the box; before the first fit every task is uniform (the bootstrap), or, with
``bootstrap_spread`` set, drawn near the space's easiest task: the expert-knowledge variant that
TeachMyAgent (Romac et al. 2021) benchmarks, for students that learn nothing from uniform tasks.
With ``target_task_ratio`` set, that share of tasks, from the first on, is the space's hardest task:
for a student tested there whose other tasks rarely reach all of it (the KUKA space's ``rnd_*``
parameters shrink the block's placement range, so outer placements are rare in any spread of tasks).

Two changes from the reference code, each switchable: tasks are rescaled to [0, 1] per dimension
before the nearest-neighbour search and the fit (in raw units a parameter spanning 0.04 next to
one spanning 0.89 barely counts), and rewards can be mapped onto [0, 1] from a known range.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Mapping
from typing import Annotated, Any

import numpy as np
from pydantic import Field, model_validator

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.algorithms.learning_progress import MIN_HISTORY_FOR_ALP, NearestTree, ProgressHistory
from teacher_service.teachers.base import BuildJob, EpisodeResult, FitJob
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms, standard_normals
from teacher_service.teachers.mixture import MixtureFit, MixtureParams, MixtureSampler, MixtureTeacher
from teacher_service.teachers.params import FiniteFloat
from teacher_service.teachers.row_log import RowLog
from teacher_service.teachers.state import COUNTS, STR, Items, StateField

MAX_HISTORY_WINDOW = 1_000_000
"""At 9 columns for the KUKA space, about 150 MB a curriculum at most (the rows, and room to grow)."""

RECENT_ORIGINS = 1000
"""How many recent tasks' origins (GMM or uniform) the state reports."""


class AlpGmmParams(MixtureParams):
    target_task_ratio: float = Field(default=0.0, ge=0.0, le=1.0)
    """Share of tasks that are the space's hardest task (the test), bootstrap included; the rest as
    ``random_task_ratio`` says."""
    buffer_size: int = Field(default=500, ge=1, le=10_000)
    """Newest tasks scanned directly before joining the k-d tree that answers nearest-neighbour
    queries; affects speed only."""
    history_window: int = Field(default=100_000, ge=10_000, le=MAX_HISTORY_WINDOW)
    """Most recent results searched for a task's nearest earlier task (its learning progress is
    the change in reward from there); older ones leave memory once stored. The reference keeps
    them all: the two agree until this many results."""
    rescale_tasks: bool = True
    """Measure distances and fit mixtures on tasks rescaled to [0, 1] per dimension."""
    reward_range: Annotated[list[FiniteFloat], Field(min_length=2, max_length=2)] | None = None
    """[low, high] mapped onto [0, 1] (clipped) before ALP is computed; null keeps raw rewards.
    ALP values in the state are in these normalised units when set."""
    bootstrap_spread: Annotated[FiniteFloat, Field(ge=0.0, le=10.0)] | None = None
    """Null: bootstrap tasks are uniform. Otherwise they come from a Gaussian on the easiest task with
    this standard deviation per dimension, in units of the dimension's width, clipped to the box."""

    @model_validator(mode="after")
    def _consistent(self) -> AlpGmmParams:
        if self.target_task_ratio + self.random_task_ratio > 1.0:
            raise ValueError(
                f"target_task_ratio ({self.target_task_ratio}) and random_task_ratio ({self.random_task_ratio}) "
                "cannot add up to more than 1"
            )
        if self.reward_range is not None and not self.reward_range[0] < self.reward_range[1]:
            raise ValueError(f"reward_range must have low < high, got {self.reward_range}")
        return self


class AlpGmmTeacher(MixtureTeacher):
    """Absolute-learning-progress teacher over a Gaussian mixture (see the module docstring)."""

    kind = "alp-gmm"
    Params = AlpGmmParams
    params: AlpGmmParams
    extra_coordinates = 1
    state_fields = (
        *MixtureTeacher.state_fields,
        StateField("origins", COUNTS),
        StateField("recent_origins", Items(STR), "_recent_origins"),
    )

    def __init__(self, space: TaskSpace, seed: int, params: AlpGmmParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        self._easiest_unit: np.ndarray | None = None
        if self.params.bootstrap_spread is not None:
            try:
                self._easiest_unit = space.to_unit(space.to_array(space.easiest()))
            except ValueError as error:
                raise ValueError(f"bootstrap_spread needs an easiest value for every parameter: {error}") from None
        self._target: np.ndarray | None = None
        if self.params.target_task_ratio > 0:
            try:
                self._target = space.to_array(space.hardest())
            except ValueError as error:
                raise ValueError(f"target_task_ratio needs a hardest value for every parameter: {error}") from None
        self._history = ProgressHistory(len(space), self.params.buffer_size, self.params.history_window)
        self.origins: Counter[str] = Counter(gmm=0, uniform=0)
        self._recent_origins: deque[str] = deque(maxlen=RECENT_ORIGINS)

    def _draw(self, first_index: int, count: int) -> list[Task]:
        dims = len(self.space)
        # Per task: origin coin, component choice, d normal quantiles, d uniform coordinates.
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, 2 + 2 * dims)
        normal_quantiles = uniforms[:, 2 : 2 + dims]
        tasks = self.space.from_unit(uniforms[:, 2 + dims :])
        # The first uniform picks the origin: target below target_task_ratio, then uniform, then the GMM.
        to_target = uniforms[:, 0] < self.params.target_task_ratio
        if self._sampler is not None:
            from_gmm = uniforms[:, 0] >= self.params.target_task_ratio + self.params.random_task_ratio
            features = self._sampler.draw(uniforms[:, 1], normal_quantiles)
            tasks = np.where(from_gmm[:, None], self._to_task_units(features), tasks)
            origins = ["gmm" if gmm else "uniform" for gmm in from_gmm]
        elif self._easiest_unit is not None:
            near_easiest = self._easiest_unit + self.params.bootstrap_spread * standard_normals(normal_quantiles)
            tasks = self.space.from_unit(np.clip(near_easiest, 0.0, 1.0))
            origins = ["near-easiest"] * count
        else:
            origins = ["uniform"] * count
        if self._target is not None:
            tasks = np.where(to_target[:, None], self._target, tasks)
            origins = ["target" if target else origin for target, origin in zip(to_target, origins, strict=True)]
        self.origins.update(origins)
        self._recent_origins.extend(origins)
        return [self.space.from_array(row) for row in tasks]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        features = self._to_features(self.space.to_array(result.task))
        reward = self._scaled(result.reward)
        distance, nearest_reward = self._history.nearest(features)
        alp = abs(reward - nearest_reward) if self._history.size >= MIN_HISTORY_FOR_ALP else 0.0
        self._history.add(features, reward, alp, repeat=distance == 0.0)
        if self.results_seen % self.params.fit_rate:
            return None
        self.fits_requested += 1
        return self.refit_job(self.fits_requested - 1)

    def _fit_points(self, start: int, stop: int) -> np.ndarray:
        """Task features and ALP, all still in the history."""
        return self._history.fit_points(start, stop)

    def build_job(self) -> BuildJob | None:
        return self._history.pending_build()

    def adopt_build(self, job: BuildJob, output: Any) -> None:
        if not isinstance(output, NearestTree):
            raise TypeError(f"expected the tree a BuildJob returns, got {type(output).__name__}")
        self._history.adopt(job, output)

    def _prepare(self, fit: MixtureFit) -> MixtureSampler:
        """Components picked by their mean ALP (the last coordinate), clipped at 0."""
        return MixtureSampler.prepare(fit, np.clip(fit.means[:, -1], 0.0, None), len(self.space))

    def _history_rows(self) -> RowLog:
        """One row per result: its task features, its (scaled) reward, its ALP, and 1.0 when an
        earlier result had the same task features (else 0.0)."""
        return self._history.log

    def _export(self) -> dict[str, Any]:
        return {"history_rows": self._history.size, "history_from": self._history.kept_from, **super()._export()}

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        self._history.restore(history, int(state.get("history_from", 0)), int(state["history_rows"]))
        super()._import(state, history)

    @property
    def recent_alps(self) -> np.ndarray:
        """ALP of the last ``fit_rate`` results: the data the next fit will see."""
        return self._history.alps(max(self._history.size - self.params.fit_rate, 0))

    def _to_features(self, tasks: np.ndarray) -> np.ndarray:
        return self.space.to_unit(tasks) if self.params.rescale_tasks else np.asarray(tasks, dtype=np.float64)

    def _to_task_units(self, features: np.ndarray) -> np.ndarray:
        return self.space.from_unit(features) if self.params.rescale_tasks else features

    def _scaled(self, reward: float) -> float:
        if self.params.reward_range is None:
            return reward
        low, high = self.params.reward_range
        return min(max((reward - low) / (high - low), 0.0), 1.0)

    def _describe(self) -> dict[str, Any]:
        alps = self.recent_alps
        return {
            "bootstrapping": self._sampler is None,
            "fits": self.fits_installed,
            "fits_requested": self.fits_requested,
            "last_fit_index": self._sampler.fit.index if self._sampler else None,
            "next_fit_at_results": (self.results_seen // self.params.fit_rate + 1) * self.params.fit_rate,
            "recent_mean_alp": float(alps.mean()) if len(alps) else None,
            "components": self._components(),
            "aic_by_components": (
                {str(k): aic for k, aic in self._sampler.fit.aic_by_components.items()} if self._sampler else {}
            ),
            "task_origins": dict(self.origins),
            "recent_task_origins": list(self._recent_origins),
        }

    def _components(self) -> list[dict[str, Any]]:
        if self._sampler is None:
            return []
        fit = self._sampler.fit
        scale = (self.space.high - self.space.low) if self.params.rescale_tasks else np.ones(len(self.space))
        components = []
        for weight, mean, covariance, probability in zip(
            fit.weights, fit.means, fit.covariances, self._sampler.probabilities, strict=True
        ):
            task_mean = self._to_task_units(mean[:-1])
            components.append(
                {
                    "weight": float(weight),
                    "mean": {name: float(v) for name, v in zip(self.space.names, task_mean, strict=True)},
                    "covariance": (covariance[:-1, :-1] * np.outer(scale, scale)).tolist(),
                    "mean_alp": float(mean[-1]),
                    "sampling_probability": float(probability),
                }
            )
        return components
