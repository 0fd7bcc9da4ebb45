"""RIAC (Baranes and Oudeyer 2009): split the task space where learning progress differs, sample by progress.

The space is a tree of boxes (regions). Each result joins every region that contains its task, and
each region keeps its latest ``max_region_size + 1`` results. A region's progress is the absolute
difference between the mean reward of the older and the newer half of its latest ``alp_window``
results. When a leaf holds more than ``max_region_size`` results it tries ``split_attempts`` cuts,
each at a random dimension and a uniform threshold, keeping only cuts that leave at least
``min_region_results`` results on each side; among those whose halves are each at least
``min_width_ratio`` of the box wide, the cut whose halves' progress differs most wins (ties go to
the later cut). When no cut qualifies, the leaf drops its oldest ``discard_ratio`` share of results.

A task comes from one of three modes: with probability ``mutation_ratio`` the lowest-reward task of a
region picked in proportion to progress, moved by a Gaussian of ``mutation_std`` per dimension
(in units of the dimension's width) and clipped into the region; with probability
``random_task_ratio`` uniformly from the box; otherwise uniformly from a region picked in proportion
to progress. Regions are picked among all regions (parents included) as in the reference, or among
leaves only; uniformly when none shows progress.

This follows the teachDeepRL implementation (Portelas et al. 2019) and its defaults, written anew:
regions are boxes in [0, 1]-rescaled task coordinates; a task on a cut belongs to the upper half
only; a region keeps the indices of its results in the teacher's history; a cut's score is the
progress difference alone (the reference multiplies it by the lengths of two two-element lists, a
constant); new halves start with their own progress (the reference gives them the last attempt's);
threshold draws per attempt are capped (``CANDIDATES_PER_ATTEMPT``) where the reference loops until
one fits; the tree stops growing at ``max_regions``; every draw is addressed by the task's index.
Splits run inline in ``learn``: one costs about a millisecond with the defaults (measured on a
busy two-core machine), no more than an HTTP request.

When it helps: students whose competence grows region by region; TeachMyAgent found RIAC best on
some bodies of its Parkour benchmark. It needs no model fit, so it adapts after every result.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import Field, model_validator

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms, standard_normals
from teacher_service.teachers.params import TeacherParams
from teacher_service.teachers.row_log import RowLog
from teacher_service.teachers.state import INT, StateField

SPLIT_STREAM = 2
"""The random stream that split searches draw their cuts from (``draws`` has tasks and fits)."""

CANDIDATES_PER_ATTEMPT = 20
"""Threshold draws allowed per split attempt before the search gives up on finding the rest."""

MUTATION_MARGIN = 1e-5
"""Mutated tasks stay this far (unit coordinates) inside their region's walls, as in the reference."""

MAX_REGION_SIZE = 1000
MAX_REGIONS = 10_000
"""Together these bound memory: at most 10,000 regions of 1,001 result indices each."""


class RiacParams(TeacherParams):
    max_region_size: int = Field(default=200, ge=10, le=MAX_REGION_SIZE)
    """Results a leaf holds before it splits; every region keeps this many plus one, newest last."""
    alp_window: int | None = Field(default=None, ge=2, le=MAX_REGION_SIZE + 1)
    """Latest results of a region its progress is measured on; null means ``max_region_size``."""
    split_attempts: int = Field(default=50, ge=1, le=200)
    """Random cuts tried per split."""
    min_region_results: int | None = Field(default=None, ge=1, le=MAX_REGION_SIZE // 2)
    """Results each half of a cut must hold; null means ``max_region_size / 20`` rounded up."""
    min_width_ratio: float = Field(default=1 / 15, ge=0.0, le=0.5)
    """Narrowest a half may be in any dimension, as a share of that dimension's width."""
    discard_ratio: float = Field(default=0.25, gt=0.0, le=1.0)
    """Share of a full leaf's oldest results dropped when none of its cuts qualifies."""
    max_regions: int = Field(default=2000, ge=1, le=MAX_REGIONS)
    """Most regions the tree grows to (each split adds two); past it, full leaves discard instead."""
    random_task_ratio: float = Field(default=0.2, ge=0.0, le=1.0)
    """Share of tasks drawn uniformly from the whole box."""
    mutation_ratio: float = Field(default=0.1, ge=0.0, le=1.0)
    """Share of tasks that mutate the lowest-reward task of a region picked by progress."""
    mutation_std: float = Field(default=0.1, ge=0.0, le=1.0)
    """Standard deviation of a mutation per dimension, in units of the dimension's width."""
    leaves_only: bool = False
    """Pick regions among leaves only, rather than among all regions (the reference's default)."""

    @model_validator(mode="after")
    def _consistent(self) -> RiacParams:
        if self.random_task_ratio + self.mutation_ratio > 1.0:
            raise ValueError(
                f"random_task_ratio ({self.random_task_ratio}) and mutation_ratio ({self.mutation_ratio}) "
                "cannot add up to more than 1"
            )
        if self.min_region_results is not None and 2 * self.min_region_results > self.max_region_size + 1:
            raise ValueError(
                f"min_region_results ({self.min_region_results}) cannot exceed half of max_region_size + 1 "
                f"({self.max_region_size + 1}): no cut could ever qualify"
            )
        return self

    @property
    def window(self) -> int:
        return self.max_region_size if self.alp_window is None else self.alp_window

    @property
    def min_results(self) -> int:
        if self.min_region_results is not None:
            return self.min_region_results
        return math.ceil(self.max_region_size / 20)


def progress(rewards: np.ndarray, window: int) -> float:
    """Absolute difference of the mean rewards of the older and newer half of the last ``window``
    rewards (the older half takes the odd one); 0 for two rewards or fewer."""
    count = len(rewards)
    if count <= 2:
        return 0.0
    span = min(count, window)
    half = span // 2
    return abs(float(rewards[count - span : count - half].mean()) - float(rewards[count - half :].mean()))


@dataclass
class _Region:
    """A box in unit task coordinates, and its latest results, oldest first: their history row
    indices and their values (unit task, reward), so the history itself need not stay in memory.

    It holds the last ``max_region_size + 1`` results inside it whose index is at least ``cutoff``,
    so ``cutoff`` and the history from its oldest result on are enough to rebuild it."""

    low: np.ndarray
    high: np.ndarray
    cutoff: int
    rows: np.ndarray
    values: np.ndarray
    progress: float = 0.0
    cut: tuple[int, float, int, int] | None = None
    """For a split region: (dimension, threshold, lower half's id, upper half's id)."""


class RiacTeacher(Teacher):
    """Region-splitting learning-progress teacher (see the module docstring)."""

    kind = "riac"
    Params = RiacParams
    params: RiacParams
    state_fields = (StateField("split_searches", INT), StateField("splits", INT), StateField("discards", INT))

    def __init__(self, space: TaskSpace, seed: int, params: RiacParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        self._dims = len(space)
        self._log = RowLog(self._dims + 1, 1024)
        self._regions = [self._root()]
        self.split_searches = 0
        self.splits = 0
        self.discards = 0
        self._choices = np.zeros(1, dtype=np.intp)
        self._choice_cdf = np.ones(1)
        self._refresh_choice()

    def _root(self) -> _Region:
        empty = np.empty((0, self._dims + 1))
        return _Region(np.zeros(self._dims), np.ones(self._dims), 0, np.empty(0, dtype=np.intp), empty)

    def _draw(self, first_index: int, count: int) -> list[Task]:
        dims = self._dims
        # Per task: mode, region choice, d coordinates (uniforms, or normal quantiles for a mutation).
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, 2 + dims)
        mutate_below = self.params.mutation_ratio
        random_below = mutate_below + self.params.random_task_ratio
        picks = np.minimum(np.searchsorted(self._choice_cdf, uniforms[:, 1], side="right"), len(self._choices) - 1)
        features = uniforms[:, 2:].copy()
        for row, (mode, pick) in enumerate(zip(uniforms[:, 0], picks, strict=True)):
            if random_below <= mode or mode < mutate_below:
                region = self._regions[self._choices[pick]]
                if mode < mutate_below and len(region.rows):
                    worst = region.values[np.argmin(region.values[:, -1]), :dims]
                    moved = worst + self.params.mutation_std * standard_normals(features[row])
                    features[row] = np.clip(moved, region.low + MUTATION_MARGIN, region.high - MUTATION_MARGIN)
                else:
                    features[row] = region.low + features[row] * (region.high - region.low)
        return [self.space.from_array(row) for row in self.space.from_unit(features)]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        features = self.space.to_unit(self.space.to_array(result.task))
        values = np.append(features, result.reward)
        row = self._log.size
        self._log.append(values)
        self._log.needed_from = self._log.size  # the regions hold what they read
        path = [0]
        while (cut := self._regions[path[-1]].cut) is not None:
            dim, threshold, lower, upper = cut
            path.append(lower if features[dim] < threshold else upper)
        capacity = self.params.max_region_size + 1
        for region_id in path:
            region = self._regions[region_id]
            region.rows = np.append(region.rows, row)[-capacity:]
            region.values = np.concatenate([region.values, values[None]])[-capacity:]
        if len(self._regions[path[-1]].rows) > self.params.max_region_size:
            self._split_or_discard(path[-1])
        for region_id in path:
            region = self._regions[region_id]
            region.progress = progress(region.values[:, -1], self.params.window)
        self._refresh_choice()
        return None

    def _split_or_discard(self, region_id: int) -> None:
        region = self._regions[region_id]
        cut = self._best_cut(region) if len(self._regions) + 2 <= self.params.max_regions else None
        if cut is None:
            drop = max(1, int(self.params.max_region_size * self.params.discard_ratio))
            region.rows, region.values = region.rows[drop:], region.values[drop:]
            region.cutoff = int(region.rows[0])
            self.discards += 1
            return
        dim, threshold = cut
        lower_high, upper_low = region.high.copy(), region.low.copy()
        lower_high[dim] = upper_low[dim] = threshold
        below = region.values[:, dim] < threshold
        lower_id, upper_id = len(self._regions), len(self._regions) + 1
        for low, high, side in ((region.low, lower_high, below), (upper_low, region.high, ~below)):
            half = _Region(low.copy(), high, int(region.rows[0]), region.rows[side], region.values[side])
            half.progress = progress(half.values[:, -1], self.params.window)
            self._regions.append(half)
        region.cut = (dim, threshold, lower_id, upper_id)
        self.splits += 1

    def _best_cut(self, region: _Region) -> tuple[int, float] | None:
        """The qualifying cut whose halves' progress differs most, or ``None``."""
        generator = np.random.default_rng([self.seed, SPLIT_STREAM, self.split_searches])
        self.split_searches += 1
        attempts = self.params.split_attempts
        candidates = attempts * CANDIDATES_PER_ATTEMPT
        dims = generator.integers(self._dims, size=candidates)
        thresholds = region.low[dims] + generator.random(candidates) * (region.high - region.low)[dims]
        points = region.values[:, :-1]
        rewards = region.values[:, -1]
        below = points[:, dims] < thresholds
        counts = below.sum(axis=0)
        least = self.params.min_results
        populated = np.flatnonzero((counts >= least) & (len(rewards) - counts >= least))[:attempts]
        narrowest = self.params.min_width_ratio
        best: tuple[int, float] | None = None
        best_score = 0.0
        for candidate in populated:
            dim, threshold = int(dims[candidate]), float(thresholds[candidate])
            if threshold - region.low[dim] < narrowest or region.high[dim] - threshold < narrowest:
                continue
            mask = below[:, candidate]
            window = self.params.window
            score = abs(progress(rewards[mask], window) - progress(rewards[~mask], window))
            if score >= best_score:
                best, best_score = (dim, threshold), score
        return best

    def _refresh_choice(self) -> None:
        if self.params.leaves_only:
            choices = [i for i, region in enumerate(self._regions) if region.cut is None]
        else:
            choices = list(range(len(self._regions)))
        weights = np.array([self._regions[i].progress for i in choices])
        total = weights.sum()
        probabilities = weights / total if total > 0 else np.full(len(choices), 1.0 / len(choices))
        self._choices = np.array(choices, dtype=np.intp)
        self._choice_cdf = np.cumsum(probabilities)

    def _history_rows(self) -> RowLog:
        """One row per result: its task in unit coordinates and its reward."""
        return self._log

    def _oldest_held(self) -> int:
        """The oldest history row any region holds: a restore reads the history from there."""
        return min((int(region.rows[0]) for region in self._regions if len(region.rows)), default=self._log.size)

    def _export(self) -> dict[str, Any]:
        return {
            "history_rows": self._log.size,
            "history_from": self._oldest_held(),
            **super()._export(),
            "regions": [[region.cutoff, None if region.cut is None else list(region.cut)] for region in self._regions],
        }

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        first = int(state.get("history_from", 0))
        self._log.load(history, first, int(state["history_rows"]))
        super()._import(state, history)
        # Halves are numbered after the region they split, though not next to it: regions split in
        # the order the results made them, so walking the ids in order meets every parent first.
        entries = state["regions"]
        regions: list[_Region | None] = [self._root()] + [None] * (len(entries) - 1)
        for region_id, (cutoff, cut) in enumerate(entries):
            region = regions[region_id]
            if region is None:
                raise ValueError(f"region {region_id} is not a half of any region before it")
            region.cutoff = int(cutoff)
            if cut is not None:
                dim, threshold, lower, upper = int(cut[0]), float(cut[1]), int(cut[2]), int(cut[3])
                if not (region_id < lower < len(entries) and region_id < upper < len(entries)) or lower == upper:
                    raise ValueError(f"region {region_id}'s halves {lower} and {upper} must be later, distinct regions")
                if regions[lower] is not None or regions[upper] is not None:
                    raise ValueError(f"region {region_id}'s halves {lower} and {upper} are halves of another region")
                region.cut = (dim, threshold, lower, upper)
                lower_high, upper_low = region.high.copy(), region.low.copy()
                lower_high[dim] = upper_low[dim] = threshold
                regions[lower] = _Region(region.low.copy(), lower_high, 0, region.rows, region.values)
                regions[upper] = _Region(upper_low, region.high.copy(), 0, region.rows, region.values)
        self._regions = [region for region in regions if region is not None]
        if len(self._regions) != len(entries):
            raise ValueError("some regions of the snapshot are halves of no region")
        self._refill(first)
        self._log.needed_from = self._log.size
        self._refresh_choice()

    def _refill(self, first: int) -> None:
        """Give each region its rows from the history: partition the rows from ``first`` (the
        oldest any region held) down the tree, then keep each region's last
        ``max_region_size + 1`` at or after its cutoff."""
        capacity = self.params.max_region_size + 1
        history = self._log.view(first)
        pending = [(0, np.arange(first, self._log.size, dtype=np.intp))]
        while pending:
            region_id, rows = pending.pop()
            region = self._regions[region_id]
            if region.cut is not None:
                dim, threshold, lower, upper = region.cut
                below = history[rows - first, dim] < threshold
                pending += [(lower, rows[below]), (upper, rows[~below])]
            region.rows = rows[rows >= region.cutoff][-capacity:]
            region.values = history[region.rows - first]
            region.progress = progress(region.values[:, -1], self.params.window)

    def _describe(self) -> dict[str, Any]:
        chance = np.zeros(len(self._regions))
        chance[self._choices] = np.diff(self._choice_cdf, prepend=0.0)
        return {
            "splits": self.splits,
            "discards": self.discards,
            "regions": [
                {
                    "low": self.space.from_array(self.space.from_unit(region.low)),
                    "high": self.space.from_array(self.space.from_unit(region.high)),
                    "progress": region.progress,
                    "results": len(region.rows),
                    "leaf": region.cut is None,
                    "sampling_probability": float(probability),
                }
                for region, probability in zip(self._regions, chance, strict=True)
            ],
        }
