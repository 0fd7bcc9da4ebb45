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

import functools
import math
from collections import Counter, deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, cast

import numpy as np
from pydantic import Field, model_validator
from scipy.spatial import cKDTree

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.base import BuildJob, EpisodeResult, FitJob
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms, standard_normals
from teacher_service.teachers.mixture import MixtureFit, MixtureParams, MixtureSampler, MixtureTeacher
from teacher_service.teachers.params import FiniteFloat
from teacher_service.teachers.row_log import RowLog

MIN_HISTORY_FOR_ALP = 6
"""ALP is 0 until this many earlier tasks exist, as in the reference code."""
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


TREE_GROWTH = 256
"""Once the tree is large, it is rebuilt every 1/TREE_GROWTH of its rows rather than every
``buffer_size``. Per result that costs a scan of up to two such intervals on the event loop
(~12 ns a row) plus a share of a build on a thread (~0.5 s at 1M rows); at 1M rows, an interval of
~3,900 keeps both near 0.1 ms, and leaves a build seconds to finish before it is needed."""


@dataclass(frozen=True)
class _Tree:
    """A k-d tree over the first occurrence of each position among some history rows."""

    tree: cKDTree
    rewards: np.ndarray
    """The reward of each point in the tree."""


def _build_tree(rows: np.ndarray) -> _Tree:
    """A k-d tree over ``rows`` (a view of history rows, which never change), repeats left out:
    thousands of identical points (the hardest task, repeated) cannot be split and would fill one
    leaf that every query landing there compares against (12 ms a query at 200,000 repeats, 16 us
    without them). scipy builds the tree without holding the GIL, so a thread can do it while the
    event loop answers requests."""
    firsts = np.flatnonzero(rows[:, -1] == 0.0)
    return _Tree(cKDTree(rows[firsts, :-3]), rows[firsts, -3].copy())


@dataclass
class _TreeBuild:
    size: int
    job: BuildJob
    tree: _Tree | None = None
    handed_out: bool = False


class _History:
    """Every result as a row (task features, reward, ALP, whether an earlier row has the same
    features), and the nearest earlier task among the last ``window`` rows or so.

    Older tasks sit in a k-d tree (each position once, at its first row), newer ones are scanned
    directly. Which tasks the tree holds depends only on the number of rows: at each checkpoint
    (every ``buffer_size`` rows, or every 1/TREE_GROWTH of the tree's rows once that is more) a
    tree over the last ``window`` rows so far is requested as a ``BuildJob``, and it replaces the
    current tree at the next checkpoint. The build has a whole interval to run off the event loop,
    and whoever built it (a thread, or this class itself when the output has not come back in time,
    as in a replay), the switch happens at the same row. Ties between equidistant tasks go to the
    tree, and within the scan to the earliest row, so the answers never depend on timing, and a
    repeated task is always compared with its first row while that row is in the window (a
    position whose first row has left it is left out of the tree until it is drawn again).

    Rows older than the tree's window are dropped once stored (``RowLog``), so memory stays
    bounded by the window whatever the number of results.
    """

    def __init__(self, dims: int, buffer_size: int, window: int) -> None:
        self.dims = dims
        self._buffer_size = buffer_size
        self._window = window
        self.log = RowLog(dims + 3, 2 * buffer_size)
        self._tree: _Tree | None = None
        self._tree_size = 0
        self._next_checkpoint = buffer_size
        self._build: _TreeBuild | None = None

    @property
    def size(self) -> int:
        return self.log.size

    def alps(self, start: int) -> np.ndarray:
        values: np.ndarray = self.log.view(start)[:, self.dims + 1].copy()
        return values

    def fit_points(self, start: int, stop: int) -> np.ndarray:
        """(task features, ALP) of rows ``start`` to ``stop``: the points a mixture is fitted to."""
        rows = self.log.view(start, stop)
        return np.concatenate([rows[:, : self.dims], rows[:, self.dims + 1 : self.dims + 2]], axis=1)

    def nearest(self, point: np.ndarray) -> tuple[float, float]:
        """Distance to the nearest earlier task, and its reward; (inf, nan) for an empty history."""
        distance, reward = np.inf, np.nan
        if self._tree is not None:
            # One point, so scalars; the stubs also allow the arrays a batch of points would give.
            distance, index = cast("tuple[float, np.intp]", self._tree.tree.query(point))
            reward = self._tree.rewards[index]
        if self.size > self._tree_size:
            recent = self.log.view(self._tree_size)
            offsets = recent[:, : self.dims] - point
            squared = np.einsum("ij,ij->i", offsets, offsets)
            nearest = int(np.argmin(squared))
            if math.sqrt(squared[nearest]) < distance:
                distance, reward = math.sqrt(squared[nearest]), recent[nearest, self.dims]
        return float(distance), float(reward)

    def add(self, features: np.ndarray, reward: float, alp: float, repeat: bool) -> None:
        self.log.append(np.concatenate([features, (reward, alp, float(repeat))]))
        if self.size == self._next_checkpoint:
            if self._build is not None:
                self._switch_to(self._build)
            self._request_build()

    def pending_build(self) -> BuildJob | None:
        if self._build is None or self._build.handed_out:
            return None
        self._build.handed_out = True
        return self._build.job

    def adopt(self, job: BuildJob, tree: _Tree) -> None:
        if self._build is not None and self._build.job is job:
            self._build.tree = tree

    def restore(self, rows: np.ndarray, first: int, size: int) -> None:
        """Take ``rows`` as history rows ``first`` to ``size``, with the tree and pending build a
        live run had there (``first`` is at most the tree's window start, as ``kept_from`` said)."""
        self.log.load(rows, first, size)
        passed = [0, 0]  # the last two checkpoints at or before the last row
        while self._next_checkpoint <= self.size:
            passed = [passed[1], self._next_checkpoint]
            self._next_checkpoint = self._advance(self._next_checkpoint)
        if passed[0]:
            self._switch_to(_TreeBuild(passed[0], self._tree_job(passed[0], passed[1])))
        if passed[1]:
            self._build = _TreeBuild(passed[1], self._tree_job(passed[1], self._next_checkpoint))

    @property
    def kept_from(self) -> int:
        """The oldest row a restore needs: the start of the current tree's window."""
        return self.log.needed_from

    def _window_start(self, size: int) -> int:
        return max(0, size - self._window)

    def _advance(self, checkpoint: int) -> int:
        return checkpoint + max(self._buffer_size, min(checkpoint, self._window) // TREE_GROWTH)

    def _request_build(self) -> None:
        self._next_checkpoint = self._advance(self.size)
        self._build = _TreeBuild(self.size, self._tree_job(self.size, self._next_checkpoint))

    def _tree_job(self, size: int, needed_at: int) -> BuildJob:
        return BuildJob(needed_at, functools.partial(_build_tree, self.log.view(self._window_start(size), size)))

    def _switch_to(self, build: _TreeBuild) -> None:
        self._tree = build.tree if build.tree is not None else build.job.run()
        self._tree_size = build.size
        self.log.needed_from = self._window_start(build.size)


class AlpGmmTeacher(MixtureTeacher):
    """Absolute-learning-progress teacher over a Gaussian mixture (see the module docstring)."""

    kind = "alp-gmm"
    Params = AlpGmmParams
    params: AlpGmmParams
    extra_coordinates = 1

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
        self._history = _History(len(space), self.params.buffer_size, self.params.history_window)
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
        if not isinstance(output, _Tree):
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
        return {
            "history_rows": self._history.size,
            "history_from": self._history.kept_from,
            **self._export_fits(),
            "origins": dict(self.origins),
            "recent_origins": list(self._recent_origins),
        }

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        self._history.restore(history, int(state.get("history_from", 0)), int(state["history_rows"]))
        self._import_fits(state)
        self.origins = Counter({str(origin): int(count) for origin, count in state["origins"].items()})
        self._recent_origins.extend(str(origin) for origin in state["recent_origins"])

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
