"""A lesson plan: one task per lesson, moving on when the student is good enough at the current one.

The plan comes from the book's chapter 14 (the KUKA grasp): each lesson is one task, and when the
mean reward of the current lesson's recent episodes exceeds a threshold the curriculum moves one
lesson on: jp2 and jp4 step 0.1 toward their hardest values, each rnd_* steps 0.05 toward its
hardest, and bias_obj_y jumps to its hardest once everything else is there. Over the KUKA space
that plan is still the default, with the book's outcomes.

Beyond the book, for any task space: the lessons may be given as a list of tasks, or be ``steps``
points evenly spaced from the easiest (or ``start``) to the hardest point (the default over a space
that is not the book's); the metric may be the success rate instead of the mean reward; and the
plan may step back a lesson when the metric falls below ``step_back_below``, which answers the
book's open question ("What if the agent fails in a lesson? Should it go back to the previous
lesson?") with an option: off by default, as in the book. It helps when the difficulty is known to
grow along one path through the space and a person can say what "good enough" means; automatic
teachers (ALP-GMM and the rest) are for when neither is known.
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.params import FiniteFloat, TaskParam, TeacherParams, in_space
from teacher_service.teachers.performance import RETURN_SCALE, ReturnScale
from teacher_service.teachers.state import FLOAT, INT, STR, Items, Record, StateField

LESSON_STEPS: dict[str, float] = {
    "rnd_obj_x": 0.05,
    "rnd_obj_y": 0.05,
    "rnd_obj_ang": 0.05,
    "jp2": 0.1,
    "jp4": 0.1,
}
"""How far each parameter moves toward its hardest value per lesson (the book's deltas)."""

LAST_PARAMETER = "bias_obj_y"
"""Jumps straight to its hardest value in the lesson where every stepped parameter arrives."""

SNAP = 1e-9
"""Steps that land this close to the hardest value count as arrived (0.05 sums are inexact)."""


MAX_LESSONS = 1000
"""Most lessons a plan may have: the plan is built when the curriculum is created."""


def next_lesson(lesson: Task, hardest: Task) -> Task:
    """The book's ``increase_difficulty``: one lesson harder, never past the hardest values."""
    harder = dict(lesson)
    for name, step in LESSON_STEPS.items():
        gap = hardest[name] - lesson[name]
        harder[name] = hardest[name] if abs(gap) <= step + SNAP else lesson[name] + math.copysign(step, gap)
    if all(harder[name] == hardest[name] for name in LESSON_STEPS):
        harder[LAST_PARAMETER] = hardest[LAST_PARAMETER]
    return harder


def lesson_plan(start: Task, hardest: Task) -> list[Task]:
    """Every lesson from ``start`` up to and including the hardest task.

    Raises ``ValueError`` when the plan would exceed ``MAX_LESSONS``, or when a step is lost to
    floating-point rounding at the parameters' magnitude (the plan would never arrive)."""
    lessons = 1 + max(
        math.ceil(max(abs(hardest[name] - start[name]) - SNAP, 0.0) / step) for name, step in LESSON_STEPS.items()
    )
    if lessons > MAX_LESSONS:
        raise ValueError(
            f"the lesson plan from {start} to {hardest} would have {lessons} lessons, more than {MAX_LESSONS}: "
            "choose a start closer to the hardest task or a narrower space"
        )
    plan = [dict(start)]
    while plan[-1] != hardest:
        if len(plan) == lessons:
            raise ValueError(
                f"the lesson plan from {start} to {hardest} does not arrive: steps of "
                f"{min(LESSON_STEPS.values())} are lost to rounding at these parameter values"
            )
        plan.append(next_lesson(plan[-1], hardest))
    return plan


DEFAULT_STEPS = 10
"""Lessons of the interpolated plan when none is asked for over a space that is not the book's."""

MAX_MOVES = 1000
"""Newest moves (advances and steps back) kept in the state; a plan that keeps stepping back and
forth would otherwise grow its snapshot with every move."""

Metric = Literal["reward", "success"]

LEARNED_SHARE = 0.75
"""A null ``threshold``: the share of the way from the lowest to the highest reward seen that the
window's mean must pass (or the success rate, with the success metric). The ALP-GMM paper's toy
counts a cube mastered at three quarters of its best reward."""


def interpolated_plan(start: Task, hardest: Task, steps: int, space: TaskSpace) -> list[Task]:
    """``steps`` lessons evenly spaced from ``start`` to ``hardest``, both included exactly."""
    fractions = [index / (steps - 1) for index in range(steps)]
    lessons = [{name: (1.0 - t) * start[name] + t * hardest[name] for name in space.names} for t in fractions]
    return [space.from_array(space.to_array(lesson)) for lesson in lessons]


def refuse_indistinct(plan: list[Task]) -> None:
    """Raise ``ValueError`` when two consecutive lessons are closer than results can tell apart:
    the results of one would count toward the other."""
    for index, (lesson, following) in enumerate(zip(plan, plan[1:], strict=False)):
        if all(abs(following[name] - value) <= SNAP for name, value in lesson.items()):
            raise ValueError(
                f"lessons {index} and {index + 1} of the plan are the same task ({lesson}): the steps are "
                "lost to rounding, or the start is the hardest point"
            )


class ManualParams(TeacherParams):
    start: TaskParam | None = None
    """First lesson of a computed plan (the book's or an interpolated one); null starts at the
    space's easiest point, as the book does."""
    lessons: list[TaskParam] | None = Field(default=None, min_length=1, max_length=MAX_LESSONS)
    """The lessons in order, one task each; null computes them (see ``steps``)."""
    steps: int | None = Field(default=None, ge=2, le=MAX_LESSONS)
    """Lessons evenly spaced from ``start`` (or the easiest point) to the hardest point, both
    included; null means the book's plan over the book's KUKA space, and 10 lessons over any other."""
    metric: Metric = "reward"
    """What the window averages: each episode's reward, or its success (1 or 0; results that carry
    no success flag are then left out)."""
    threshold: FiniteFloat | None = None
    """Move on when the window's mean exceeds this (the book's KUKA plan, which ``train`` gives:
    reward 5.5; a success rate lies in [0, 1)). Null learns the reward's scale: move on when the
    mean reward lies more than ``LEARNED_SHARE`` of the way from the lowest to the highest reward
    seen so far; with the success metric, null is a success rate of ``LEARNED_SHARE``."""
    step_back_below: FiniteFloat | None = None
    """Go back one lesson when the window's mean falls below this, in the units of ``threshold``,
    which it then needs; null never goes back, as the book."""
    window: int = Field(default=100, ge=1, le=10_000)
    """Recent episodes of the current lesson that are averaged (RLlib's smoothing window, which
    the book's callback read)."""
    min_episodes: int = Field(default=50, ge=1, le=10_000)
    """Episodes of the current lesson needed before it can end, so one lucky streak does not."""

    @model_validator(mode="after")
    def _consistent(self) -> ManualParams:
        if self.min_episodes > self.window:
            raise ValueError(f"min_episodes ({self.min_episodes}) cannot exceed window ({self.window})")
        if self.lessons is not None and (self.start is not None or self.steps is not None):
            raise ValueError("give either lessons, or start and steps to compute them, not both")
        if self.metric == "success" and self.threshold is not None and not 0.0 <= self.threshold < 1.0:
            raise ValueError(f"a success-rate threshold lies in [0, 1), got {self.threshold}")
        if self.step_back_below is not None and self.threshold is None:
            raise ValueError(
                "step_back_below needs a threshold in the same units: give threshold (a mean reward, or a "
                "success rate with metric 'success')"
            )
        if self.step_back_below is not None and self.threshold is not None and self.step_back_below >= self.threshold:
            raise ValueError(f"step_back_below ({self.step_back_below}) must be below threshold ({self.threshold})")
        return self


class ManualTeacher(Teacher):
    """A lesson plan: hands out the current lesson's task, moves on when the student is good enough
    at it, and optionally steps back when it falls behind. Scale: a ``threshold`` in the metric's
    units, or when not given the rewards' range learned from those seen (a success rate of 0.75)."""

    kind = "manual"
    parameter_types = frozenset({"float", "integer"})
    """Over integer parameters the lessons round to whole values."""
    Params = ManualParams
    params: ManualParams
    state_fields = (
        StateField("lesson", INT),
        StateField("lesson_scores", Items(FLOAT)),
        StateField("lesson_episodes", INT),
        StateField("stale_results", INT),
        StateField("unscored_results", INT),
        StateField("moves", Items(Record({"at_results": INT, "from": INT, "to": INT, "why": STR}))),
        StateField("moves_total", INT),
        StateField("return_scale", RETURN_SCALE, "scale"),
    )

    def __init__(self, space: TaskSpace, seed: int, params: ManualParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        self.lessons = self._plan()
        refuse_indistinct(self.lessons)
        self.lesson = 0
        self.lesson_scores: deque[float] = deque(maxlen=self.params.window)
        self.lesson_episodes = 0
        self.stale_results = 0
        self.unscored_results = 0
        self.moves: deque[dict[str, Any]] = deque(maxlen=MAX_MOVES)
        self.moves_total = 0
        self.scale = ReturnScale()

    def _plan(self) -> list[Task]:
        params, space = self.params, self.space
        if params.lessons is not None:
            return [in_space(f"lessons[{index}]", lesson, space) for index, lesson in enumerate(params.lessons)]
        start = None if params.start is None else in_space("start", params.start, space)
        try:
            start = space.easiest() if start is None else start
            hardest = space.hardest()
        except ValueError as error:
            raise ValueError(f"{error}: a computed lesson plan needs the anchors, or give lessons") from None
        if params.steps is None and set(space.names) == {*LESSON_STEPS, LAST_PARAMETER}:
            return lesson_plan(start, hardest)
        return interpolated_plan(start, hardest, params.steps or DEFAULT_STEPS, space)

    @property
    def current(self) -> Task:
        return self.lessons[self.lesson]

    def _draw(self, first_index: int, count: int) -> list[Task]:
        return [dict(self.current) for _ in range(count)]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        self.scale.see(result.reward)
        if not self._is_current(result.task):
            self.stale_results += 1
            return None
        self.lesson_episodes += 1
        if self.params.metric == "reward":
            self.lesson_scores.append(result.reward)
        elif result.success is None:
            self.unscored_results += 1
            return None
        else:
            self.lesson_scores.append(1.0 if result.success else 0.0)
        if len(self.lesson_scores) < self.params.min_episodes:
            return None
        score = statistics.fmean(self.lesson_scores)
        floor = self.params.step_back_below
        threshold = self._threshold()
        if self.lesson + 1 < len(self.lessons) and threshold is not None and score > threshold:
            self._move(self.lesson + 1, f"{self._measured(score)} > {threshold:.4g}{self._learned_note()}")
        elif self.lesson > 0 and floor is not None and score < floor:
            self._move(self.lesson - 1, f"{self._measured(score)} < {floor}")
        return None

    def _threshold(self) -> float | None:
        """The given threshold, or the learned one (none while every reward seen is the same)."""
        if self.params.threshold is not None:
            return self.params.threshold
        if self.params.metric == "success":
            return LEARNED_SHARE
        return self.scale.at(LEARNED_SHARE)

    def _learned_note(self) -> str:
        if self.params.threshold is not None or self.params.metric == "success":
            return ""
        return f" ({LEARNED_SHARE} of the way from the lowest to the highest reward seen, {self.scale.export()})"

    def _measured(self, score: float) -> str:
        what = "mean reward" if self.params.metric == "reward" else "success rate"
        return f"{what} {score:.4g} over {len(self.lesson_scores)} episodes"

    def _move(self, lesson: int, why: str) -> None:
        self.moves.append({"at_results": self.results_seen, "from": self.lesson, "to": lesson, "why": why})
        self.moves_total += 1
        self.lesson = lesson
        self.lesson_scores.clear()
        self.lesson_episodes = 0

    def _is_current(self, task: Task) -> bool:
        """Results of tasks handed out before the last move still arrive; they say nothing
        about the new lesson."""
        return all(math.isclose(task[name], value, rel_tol=0.0, abs_tol=SNAP) for name, value in self.current.items())

    def _describe(self) -> dict[str, Any]:
        return {
            "lesson": self.lesson,
            "lessons": len(self.lessons),
            "lesson_params": dict(self.current),
            "plan": [dict(lesson) for lesson in self.lessons],
            "final_lesson": self.lesson == len(self.lessons) - 1,
            "lesson_episodes": self.lesson_episodes,
            "metric": self.params.metric,
            "recent_metric": statistics.fmean(self.lesson_scores) if self.lesson_scores else None,
            "threshold": self._threshold(),
            "threshold_source": "given" if self.params.threshold is not None else "learned",
            "rewards_seen": self.scale.export(),
            "stale_results": self.stale_results,
            "unscored_results": self.unscored_results,
            "moves": [dict(move) for move in self.moves],
            "moves_total": self.moves_total,
            "advanced_at_results": [move["at_results"] for move in self.moves if move["to"] > move["from"]],
        }

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        super()._import(state, history)
        if not 0 <= self.lesson < len(self.lessons):
            raise ValueError(f"lesson {self.lesson} is not in this plan of {len(self.lessons)} lessons")
