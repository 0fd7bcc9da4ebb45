"""Learnability sampling over a box (after SFL, Rutherford et al. 2024, "No Regrets: Investigating
and Improving Regret Approximations for Curriculum Discovery").

A task the student always solves or never solves teaches it little; one it solves about half the
time teaches most. SFL scores a level by its learnability p(1 - p), p the level's success rate, and
trains on the levels that score highest. Over a continuous box no task is played twice by chance,
so p is estimated from results nearby instead of from repeated rollouts of one level.

Every ``update_every`` results the teacher rebuilds a pool of ``pool_size`` candidate tasks: a
``replay_share`` of them are tasks already played (drawn uniformly among the held results), the
rest uniform over the box. Each candidate's success rate is estimated from the ``neighbours``
nearest held results (distances in the box rescaled to [0, 1] per dimension), with
``prior_weight`` pseudo-results at ``prior_success`` added, so a candidate with few results near
it is not certain to fail: p = (successes among the neighbours + prior_weight * prior_success) /
(neighbours + prior_weight). A task is then drawn uniformly over the box with probability
``fresh_share``; otherwise a pool candidate is replayed, picked in proportion to p(1 - p) among the
``top_k`` highest-scoring ones (uniformly when none scores above 0). Before the first pool every
task is uniform.

What counts as a success: a result's own ``success`` when it carries one. Otherwise its return
compared with a bar: ``return_bar`` when given, else the midpoint of the lowest and highest return
among the held results that carry no ``success`` (a return above the midpoint succeeds; while all
those returns are equal none does). The learned bar assumes nothing about the reward scale: it sits
between the worst and the best the student has shown lately, and it is bounded by what was seen.
It moves as the student improves, so each refresh reclassifies every held result against the
current bar. On a return that is high only when the task is solved (the toy's competence, a grasp)
it splits solved from unsolved; on a return dominated by rare outliers, give ``return_bar``.

Bounds: at most ``buffer_size`` recent results are held (their unit task, return and success), and
a refresh costs a k-d tree over them plus ``pool_size`` queries of ``neighbours`` each, run inline
by the ``learn`` call that makes it due: about 8 ms with the defaults over KUKA's 6 dimensions,
about 80 ms at the parameters' bounds (measured on a busy two-core machine, load about 13), once
per ``update_every`` results. A draw is a binary search in the pool's cumulative weights.

Where this differs from SFL: SFL estimates p from fresh rollouts of each candidate level under the
current policy and keeps a buffer of the top-K levels; here p comes from the held results nearby
(no extra rollouts), candidates are sampled in proportion to learnability rather than uniformly
among the top K (``top_k`` restricts to the K best), and replays are tasks from the held results.

Over levels (an all-integer space of at most ``MAX_LEVELS`` levels) the estimate needs no
neighbours: every refresh scores every level from its own held results, p = (its successes +
prior_weight * prior_success) / (its results + prior_weight); ``pool_size``, ``replay_share`` and
``neighbours`` play no part. A level without held results has no estimate and learnability 0: it is
reached through the fresh share, a uniform level, as SFL weighs by learnability only the levels it has
rolled out. (Scored at the prior instead, p = 0.5 would make every unplayed level the most learnable
there is, and the top-K draw a sweep of the levels played least lately.) The prior still pulls a level
with few results toward 0.5: before any success, a level failed once scores above one failed ten times.
``prior_weight`` 0 gives SFL's plain success rate: every level scores 0 until one has both outcomes among
its results, and until then replays are uniform. This is SFL's p(1 - p) per level with p from the training episodes
rather than from extra rollouts, and Syllabus's ``Learnability`` with its top-K and uniform mix
(``top_k``, ``fresh_share``).

When it helps: students whose outcome is mostly solved-or-not per task, such as grasping, where
the frontier between solved and unsolved tasks is where learning happens. When it fails: a task's
success rate that is not smooth at the scale of its neighbours (the estimate blurs it), and
returns without ``success`` whose midpoint does not separate good from bad episodes.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from pydantic import Field
from scipy.spatial import cKDTree

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms
from teacher_service.teachers.levels import level_space_problem, level_table
from teacher_service.teachers.params import FiniteFloat, TeacherParams
from teacher_service.teachers.performance import UNKNOWN_SUCCESS
from teacher_service.teachers.row_log import RowLog
from teacher_service.teachers.state import INT, OPTIONAL_FLOAT, FloatArray, StateField

POOL_STREAM = 3
"""The random stream pool refreshes draw their candidates from (``draws`` has tasks and fits)."""

MAX_POOL = 1000
MAX_BUFFER = 5000
MAX_NEIGHBOURS = 64
"""Together these bound one refresh: a k-d tree over at most 5,000 results and at most 1,000
queries of 64 neighbours each."""


class LearnabilityParams(TeacherParams):
    pool_size: int = Field(default=200, ge=1, le=MAX_POOL)
    """Candidate tasks in the pool, scored by learnability at each refresh."""
    replay_share: float = Field(default=0.5, ge=0.0, le=1.0)
    """Share of the pool drawn from tasks already played (among the held results); the rest is
    uniform over the box."""
    update_every: int = Field(default=50, ge=1, le=10_000)
    """Results between two pool refreshes."""
    buffer_size: int = Field(default=2000, ge=1, le=MAX_BUFFER)
    """Most recent results held; success rates are estimated from them."""
    neighbours: int = Field(default=32, ge=1, le=MAX_NEIGHBOURS)
    """Nearest held results a candidate's success rate is estimated from."""
    prior_weight: float = Field(default=1.0, ge=0.0, le=100.0)
    """Pseudo-results at ``prior_success`` added to every estimate."""
    prior_success: float = Field(default=0.5, ge=0.0, le=1.0)
    """Success rate assumed where no results are near."""
    fresh_share: float = Field(default=0.2, ge=0.0, le=1.0)
    """Share of tasks drawn uniformly over the box instead of from the pool."""
    top_k: int | None = Field(default=20, ge=1, le=MAX_POOL)
    """Replay only the ``top_k`` highest-scoring candidates (SFL keeps its top K levels); null
    means the whole pool. On the ALP-GMM paper's toy the top 20 of 200 master clearly more than the
    whole pool (docs/results/parity.md)."""
    return_bar: FiniteFloat | None = Field(default=None, ge=-1e9, le=1e9)
    """The return above which a result without ``success`` counts as one; null means the midpoint
    of the lowest and highest return among the held results without ``success``."""


class LearnabilityTeacher(Teacher):
    """Replays the tasks the student solves about half the time: a pool of candidates (uniform and
    replayed) picked by estimated learnability p(1 - p), plus a share of fresh uniform tasks. Success
    comes from results' ``success``, else from a return bar: given, or the midpoint of the returns seen.

    See the module docstring for the estimate, the bounds and where it departs from SFL."""

    kind = "learnability"
    parameter_types = frozenset({"float", "integer"})
    Params = LearnabilityParams
    params: LearnabilityParams
    state_fields = (
        StateField("refreshes", INT),
        StateField("pool", FloatArray("the pool", rows=True), "_pool"),
        StateField("pool_success", FloatArray("the pool's success rates", rows=True), "_success"),
        StateField("return_bar", OPTIONAL_FLOAT, "_bar"),
    )

    def __init__(
        self, space: TaskSpace, seed: int, params: LearnabilityParams | Mapping[str, Any] | None = None
    ) -> None:
        super().__init__(space, seed, params)
        self._dims = len(space)
        self._log = RowLog(self._dims + 2, 2 * self.params.buffer_size)
        self.refreshes = 0
        self._pool = np.empty((0, self._dims))
        self._success = np.empty(0)
        self._bar: float | None = None
        self._cdf = np.empty(0)
        self._levels = space.level_count() if space.types == frozenset({"integer"}) else 0
        """The level count of an all-integer space (each level scored on its own), else 0 (a box)."""
        self._level_units = self._units_of_levels() if self._levels else np.empty((0, self._dims))
        """Each level's task in unit coordinates, one row per level: a refresh's pool over levels."""

    @classmethod
    def space_problem(cls, space: TaskSpace) -> str | None:
        """A box of floats, or up to ``MAX_LEVELS`` levels of integers; not both in one space."""
        if space.types == frozenset({"float", "integer"}):
            return (
                f"parameter {space.names[int(np.argmax(space.integer))]!r} is an integer parameter among float ones: "
                "the learnability teacher takes a box of float parameters or a space of integer ones (levels), not both"
            )
        return super().space_problem(space) or level_space_problem(cls.kind, space)

    def _draw(self, first_index: int, count: int) -> list[Task]:
        # Per task: fresh or replay, which candidate, and the coordinates of a fresh task.
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, 2 + self._dims)
        units = uniforms[:, 2:].copy()
        if self._levels:
            # A fresh draw is a uniform level: level i owns [i / n, (i + 1) / n) of the third uniform.
            fresh_levels = np.minimum((uniforms[:, 2] * self._levels).astype(np.int64), self._levels - 1)
            units = self._level_units[fresh_levels]
        if len(self._pool):
            replay = uniforms[:, 0] >= self.params.fresh_share
            picks = np.minimum(np.searchsorted(self._cdf, uniforms[replay, 1], side="right"), len(self._pool) - 1)
            units[replay] = self._pool[picks]
        return [self.space.from_array(row) for row in self.space.from_unit(units)]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        unit = self.space.to_unit(self.space.to_array(result.task))
        success = UNKNOWN_SUCCESS if result.success is None else float(result.success)
        self._log.append(np.concatenate([unit, [result.reward, success]]))
        self._log.needed_from = max(0, self._log.size - self.params.buffer_size)
        if self.results_seen % self.params.update_every == 0:
            self._refresh()
        return None

    def _held(self) -> np.ndarray:
        return self._log.view(max(self._log.first, self._log.size - self.params.buffer_size))

    def _outcomes(self, held: np.ndarray) -> tuple[np.ndarray, float | None]:
        """Each held result as 1 (success) or 0, and the return bar used for those without ``success``."""
        rewards, flags = held[:, -2], held[:, -1]
        unflagged = flags == UNKNOWN_SUCCESS
        bar = self.params.return_bar
        if bar is None and unflagged.any():
            bar = float((rewards[unflagged].min() + rewards[unflagged].max()) / 2)
        outcomes = flags.copy()
        if bar is not None:
            outcomes[unflagged] = (rewards[unflagged] > bar).astype(float)
        return outcomes, bar

    def _units_of_levels(self) -> np.ndarray:
        tasks = np.array([self.space.to_array(self.space.level_task(level)) for level in range(self._levels)])
        return self.space.to_unit(tasks.reshape(self._levels, self._dims))

    def _refresh_levels(self, held: np.ndarray) -> None:
        """Every level scored from its own held results, with the prior's pseudo-results."""
        self.refreshes += 1
        outcomes, self._bar = self._outcomes(held)
        tasks = [self.space.from_array(row) for row in self.space.from_unit(held[:, : self._dims])]
        played = np.array([self.space.task_level(task) for task in tasks], dtype=np.int64)
        results = np.bincount(played, minlength=self._levels)
        successes = np.bincount(played, weights=outcomes, minlength=self._levels)
        params = self.params
        self._pool = self._level_units.copy()
        known = results > 0  # a level without held results has no estimate
        self._success = np.full(self._levels, UNKNOWN_SUCCESS)
        prior = params.prior_weight * params.prior_success
        self._success[known] = (successes[known] + prior) / (results[known] + params.prior_weight)
        self._refresh_choice()

    def _refresh(self) -> None:
        """A new pool: replayed and uniform candidates, each scored from its nearest held results
        (over levels: every level, from its own)."""
        held = self._held()
        if self._levels:
            self._refresh_levels(held)
            return
        params = self.params
        generator = np.random.default_rng([self.seed, POOL_STREAM, self.refreshes])
        self.refreshes += 1
        replays = round(params.pool_size * params.replay_share)
        chosen = generator.integers(len(held), size=replays)
        fresh = generator.random((params.pool_size - replays, self._dims))
        pool = np.concatenate([held[chosen, : self._dims], fresh])
        outcomes, self._bar = self._outcomes(held)
        neighbours = min(params.neighbours, len(held))
        _, nearest = cKDTree(held[:, : self._dims]).query(pool, k=neighbours)
        nearest = np.asarray(nearest).reshape(len(pool), neighbours)
        prior = params.prior_weight * params.prior_success
        self._pool = pool
        self._success = (outcomes[nearest].sum(axis=1) + prior) / (neighbours + params.prior_weight)
        self._refresh_choice()

    def _learnability(self) -> np.ndarray:
        """p(1 - p) of each candidate; 0 for a level without results (``UNKNOWN_SUCCESS``)."""
        scores: np.ndarray = np.where(self._success >= 0.0, self._success * (1.0 - self._success), 0.0)
        return scores

    def _refresh_choice(self) -> None:
        scores = self._learnability()
        if self.params.top_k is not None and self.params.top_k < len(scores):
            # Stable order, so ties at the cut keep the earlier candidates on every machine.
            kept = np.argsort(-scores, kind="stable")[: self.params.top_k]
            mask = np.zeros(len(scores), dtype=bool)
            mask[kept] = True
            scores = np.where(mask, scores, 0.0)
        total = scores.sum()
        weights = scores / total if total > 0 else np.full(len(scores), 1.0 / max(len(scores), 1))
        self._cdf = np.cumsum(weights)

    def _history_rows(self) -> RowLog:
        """One row per result: its task in unit coordinates, its return, and its success (1, 0, or -1
        when it did not say)."""
        return self._log

    def _export(self) -> dict[str, Any]:
        return {
            "history_rows": self._log.size,
            "history_from": max(0, self._log.size - self.params.buffer_size),
            **super()._export(),
        }

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        self._log.load(history, int(state["history_from"]), int(state["history_rows"]))
        self._log.needed_from = max(0, self._log.size - self.params.buffer_size)
        super()._import(state, history)
        if len(self._success) != len(self._pool):
            raise ValueError(f"the pool has {len(self._pool)} candidates but {len(self._success)} success rates")
        self._refresh_choice()

    def _describe(self) -> dict[str, Any]:
        learnability = self._learnability()
        chance = np.diff(self._cdf, prepend=0.0) if len(self._cdf) else self._cdf
        if self._levels:
            return {"refreshes": self.refreshes, "return_bar": self._bar, **self._level_table(learnability, chance)}
        return {
            "refreshes": self.refreshes,
            "return_bar": self._bar,
            "pool_mean_learnability": float(learnability.mean()) if len(learnability) else None,
            "pool": [self.space.from_array(row) for row in self.space.from_unit(self._pool)],
            "pool_success": self._success.tolist(),
            "pool_learnability": learnability.tolist(),
            "pool_probability": (chance * (1.0 - self.params.fresh_share)).tolist(),
        }

    def _level_table(self, learnability: np.ndarray, chance: np.ndarray) -> dict[str, Any]:
        """The likeliest next levels, as the other level kinds show theirs."""
        fresh = self.params.fresh_share if len(chance) else 1.0  # uniform until the first refresh
        probability = np.full(self._levels, fresh / self._levels)
        if len(chance):
            probability += chance * (1.0 - fresh)
        if len(self._success):
            known = self._success >= 0.0  # a level without held results has no estimate
            success, learnability = np.where(known, self._success, np.nan), np.where(known, learnability, np.nan)
        else:  # no estimate before the first refresh
            success = learnability = np.full(self._levels, np.nan)
        return level_table(self.space, probability, {"success": success, "learnability": learnability})
