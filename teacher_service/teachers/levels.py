"""The level kinds: teachers that pick among the finite set of levels of an all-integer task space.

A level is one task of such a space (a level seed, a layout), numbered by ``TaskSpace.level_task``:
a Discrete space is one integer parameter, a MultiDiscrete space several. Each kind tracks a few
numbers per level, so it refuses a space of more than ``MAX_LEVELS`` levels (a 422 that says so), and
its memory, a draw and a snapshot are bounded at that cap.

- ``plr``: Prioritized Level Replay (Jiang, Grefenstette and Rocktäschel, ICML 2021), and with
  ``robust`` robust PLR (Jiang et al., NeurIPS 2021).
- ``learning-progress``: learning progress over levels (Kanitscheider et al. 2021), as Syllabus's
  online variant computes it.

``learnability`` and ``random`` also teach levels (their modules say how); the algorithms themselves
are in ``algorithms/levels.py``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import Field

from common.client.task_space import MAX_LEVELS, Task, TaskSpace
from teacher_service.teachers.algorithms.levels import LearningProgress, LevelReplay
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms
from teacher_service.teachers.params import TeacherParams
from teacher_service.teachers.state import ARRAY, StateField, export_fields, import_fields

LEVELS_SHOWN = 100
"""Levels the dashboard lists (the most likely next draws); the rest are summarised by counts."""


def level_space_problem(kind: str, space: TaskSpace) -> str | None:
    """Why a level kind cannot teach ``space``: more levels than it tracks (the types are checked first)."""
    if space.types == frozenset({"integer"}) and space.level_count() > MAX_LEVELS:
        return (
            f"the task space holds {space.level_count():,} levels (the product of its integer parameters' "
            f"value counts): the {kind} teacher tracks at most {MAX_LEVELS:,}"
        )
    return None


class _LevelTeacher(Teacher):
    """What the level kinds share: integer spaces only, tasks drawn as level numbers, the sampler's
    arrays in the snapshot, and a dashboard table of the likeliest levels."""

    parameter_types = frozenset({"integer"})
    sampler: LevelReplay | LearningProgress

    @classmethod
    def space_problem(cls, space: TaskSpace) -> str | None:
        return super().space_problem(space) or level_space_problem(cls.kind, space)

    def _level_of(self, result: EpisodeResult) -> int:
        return self.space.task_level(result.task)

    def _export(self) -> dict[str, Any]:
        return {**export_fields(self.sampler, self.sampler.state_fields), **super()._export()}

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        import_fields(self.sampler, self.sampler.state_fields, state)
        super()._import(state, history)
        self.sampler.loaded()

    def _level_table(self, columns: Mapping[str, np.ndarray]) -> dict[str, Any]:
        return level_table(self.space, self.sampler.probabilities(), columns)


def level_table(space: TaskSpace, probability: np.ndarray, columns: Mapping[str, np.ndarray]) -> dict[str, Any]:
    """The dashboard's view of a level teacher: the ``LEVELS_SHOWN`` likeliest next levels, most likely
    first, with ``columns`` per level (a NaN, such as an unscored level's score, shows as null)."""
    shown = np.argsort(-probability, kind="stable")[:LEVELS_SHOWN]
    return {
        "level_count": len(probability),
        "levels": [
            {
                "level": int(level),
                "task": space.level_task(int(level)),
                "probability": float(probability[level]),
                **{name: _number(values[level]) for name, values in columns.items()},
            }
            for level in shown
        ],
    }


def _number(value: float) -> float | None:
    return None if np.isnan(value) else float(value)


class PlrParams(TeacherParams):
    temperature: float = Field(default=0.1, gt=0.0, le=10.0)
    """β: replay weight ``(1 / rank) ** (1 / temperature)`` by score rank; lower is greedier."""
    staleness_coef: float = Field(default=0.1, ge=0.0, le=1.0)
    """ρ: the share of a replay drawn by staleness (draws since the level was last drawn) rather
    than by score, so old scores get refreshed."""
    replay_prob: float | None = Field(default=None, ge=0.0, le=1.0)
    """Once replays have begun, the chance a draw replays (``fixed``), or its cap (``proportionate``: the
    share of levels scored). Null means 1.0 for PLR, so that after its sweep every draw replays, as the
    authors' code and Syllabus do, and 0.5 for robust PLR (DCD's). Below 1, PLR keeps drawing the rest
    uniformly over all levels once every level has a score: our hybrid, which neither paper describes
    (curricula stored before this default hold 0.5, and keep it); robust PLR always replays then."""
    replay_schedule: Literal["proportionate", "fixed"] | None = None
    """How the replay probability grows (see ``replay_prob``); null means ``proportionate`` (the
    authors' default) for PLR and ``fixed`` for robust PLR, which trains on replays alone and would
    otherwise train on almost nothing until most levels had a score."""
    min_seen_share: float | None = Field(default=None, ge=0.0, le=1.0)
    """No replay until this share of the levels has a score (the authors' ρ of the schedule); null
    means 1.0 for PLR, the authors' and Syllabus's default (every level is played once, in a sweep
    without repeats, before any replay), and 0.0 for robust PLR, so that it trains from its first
    replays rather than after a whole sweep of scoring-only episodes."""
    robust: bool = False
    """Robust PLR: an exploring draw is for scoring only (``score_only`` on the task), so the learner
    trains on replayed levels alone."""


class PlrTeacher(_LevelTeacher):
    """Prioritized Level Replay over the levels of an integer space.

    Each result scores its level: the result's ``score`` when the learner sends one (the rollout workers
    send ``value_l1``, the mean absolute GAE advantage over the episode, the PLR paper's and Syllabus's
    example's score, or ``positive_value_loss``, the mean of max(GAE advantage, 0), robust PLR's: the
    trainer's ``PPOConfig.level_score`` picks), else the L1 gap between the episode's return and the
    level's previous return (the mean previous return over scored levels for a level's first result): a
    value error with the level's last return standing in for a critic.

    At its defaults PLR sweeps every level once and then only replays, as the authors' code and Syllabus's
    ``TaskSampler`` do; ``replay_prob`` below 1 gives our hybrid (see it). Departures from the authors'
    code (``facebookresearch/level-replay``) and Syllabus 0.7: draws are indexed by task number, not a
    global generator; ties in rank go to the lower level number; ranks are taken among scored levels only
    (the authors rank every level and zero the unscored); scores arrive per episode, not accumulated over
    a rollout's partial episodes; robust PLR plays its new levels on the training workers with
    ``score_only`` set, instead of on separate evaluation workers.
    """

    kind = "plr"
    Params = PlrParams
    params: PlrParams
    sampler: LevelReplay
    state_fields: ClassVar[tuple[StateField, ...]] = (StateField("returns", ARRAY),)

    def __init__(self, space: TaskSpace, seed: int, params: PlrParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        p = self.params
        schedule = p.replay_schedule or ("fixed" if p.robust else "proportionate")
        min_seen_share = p.min_seen_share if p.min_seen_share is not None else (0.0 if p.robust else 1.0)
        replay_prob = p.replay_prob if p.replay_prob is not None else (0.5 if p.robust else 1.0)
        self.sampler = LevelReplay(
            space.level_count(),
            p.temperature,
            p.staleness_coef,
            replay_prob,
            min_seen_share,
            schedule,
            replay_when_all_scored=p.robust,
        )
        self.returns = np.zeros(self.sampler.levels)
        """Each scored level's last return, the fallback score's baseline."""
        self._explored: list[bool] = []

    def _draw(self, first_index: int, count: int) -> list[Task]:
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, LevelReplay.UNIFORMS_PER_DRAW)
        draws = [self.sampler.draw(row) for row in uniforms]
        self._explored = [not replay for _, replay in draws]
        return [self.space.level_task(level) for level, _ in draws]

    def _score_only(self, first_index: int, count: int) -> list[bool]:
        return list(self._explored) if self.params.robust else [False] * count

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        level = self._level_of(result)
        score = result.score
        if score is None:
            seen = self.sampler.seen
            baseline = self.returns[level] if seen[level] else (self.returns[seen].mean() if seen.any() else 0.0)
            score = abs(result.reward - float(baseline))
        self.returns[level] = result.reward
        self.sampler.record(level, score)
        return None

    def _describe(self) -> dict[str, Any]:
        sampler = self.sampler
        return {
            "scored_levels": int(sampler.seen.sum()),
            "replay_chance": sampler.replay_chance(),
            **self._level_table(
                {
                    "score": np.where(sampler.seen, sampler.scores, np.nan),
                    "staleness": (sampler.draws - sampler.last_drawn).astype(float),
                }
            ),
        }


class LearningProgressParams(TeacherParams):
    ema_rate: float = Field(default=0.1, gt=0.0, le=1.0)
    """How far each update moves a level's fast average toward its new success rate, and the slow
    average toward the fast one."""
    reweight_theta: float = Field(default=0.1, gt=0.0, lt=0.5)
    """θ of the reweighting that stretches success rates near 0 and 1 before the gap is taken."""
    uniform_share: float = Field(default=0.25, ge=0.0, le=1.0)
    """Share of draws uniform over all levels (Syllabus's ``uniform_prob``)."""
    update_every: int = Field(default=100, ge=1, le=100_000)
    """Results between two updates of the averages (Syllabus's ``update_interval``)."""


class LearningProgressTeacher(_LevelTeacher):
    """Learning progress over the levels of an integer space: levels whose success rate is moving,
    up or down, are drawn most.

    A result's success is its ``success`` when it carries one, else whether its return is above 0.
    Departures from Syllabus 0.7's ``OnlineLearningProgress``: levels not played since the last update
    keep their averages (Syllabus folds a rate of 0 into them); draws are indexed by task number. As
    Syllabus does, the first update sets each level's baseline (its success rate then) and later
    rates count above it.
    """

    kind = "learning-progress"
    Params = LearningProgressParams
    params: LearningProgressParams
    sampler: LearningProgress

    def __init__(
        self, space: TaskSpace, seed: int, params: LearningProgressParams | Mapping[str, Any] | None = None
    ) -> None:
        super().__init__(space, seed, params)
        p = self.params
        self.sampler = LearningProgress(space.level_count(), p.ema_rate, p.reweight_theta, p.uniform_share)

    def _draw(self, first_index: int, count: int) -> list[Task]:
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, LearningProgress.UNIFORMS_PER_DRAW)
        return [self.space.level_task(self.sampler.draw(row)) for row in uniforms]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        success = result.success if result.success is not None else result.reward > 0
        self.sampler.record(self._level_of(result), float(success))
        if self.results_seen % self.params.update_every == 0:
            self.sampler.update()
        return None

    def _describe(self) -> dict[str, Any]:
        sampler = self.sampler
        return {
            "updates_pending": int(sampler.episodes.sum()),
            "updates": sampler.updates,
            "levels_with_success": int((sampler.true_rate > 0).sum()),
            **self._level_table({"progress": sampler.progress(), "fast": sampler.fast, "slow": sampler.slow}),
        }
