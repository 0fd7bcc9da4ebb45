"""The book's hand-written lesson plan for the KUKA grasp (chapter 14).

Each lesson is one task. When the mean reward of the current lesson's recent episodes exceeds a
threshold, the curriculum moves one lesson on: jp2 and jp4 step 0.1 toward their hardest values,
each rnd_* steps 0.05 toward its hardest, and bias_obj_y jumps to its hardest once everything else
is there. It never falls back.
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.params import as_float, as_int, as_task, in_space, parse_params, store

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
    """Every lesson from ``start`` up to and including the hardest task."""
    plan = [dict(start)]
    while plan[-1] != hardest:
        plan.append(next_lesson(plan[-1], hardest))
    return plan


@dataclass(frozen=True)
class ManualParams:
    start: Task | None = None
    """First lesson; None starts at the space's easiest point, as the book does."""
    threshold: float = 5.5
    """Move on when the current lesson's recent mean reward exceeds this (the book's value)."""
    window: int = 100
    """Recent episodes of the current lesson that are averaged (RLlib's smoothing window, which
    the book's callback read)."""
    min_episodes: int = 50
    """Episodes of the current lesson needed before it can end, so one lucky streak does not."""

    def __post_init__(self) -> None:
        store(
            self,
            start=as_task("start", self.start),
            threshold=as_float("threshold", self.threshold),
            window=as_int("window", self.window, minimum=1),
            min_episodes=as_int("min_episodes", self.min_episodes, minimum=1),
        )
        if self.min_episodes > self.window:
            raise ValueError(f"min_episodes ({self.min_episodes}) cannot exceed window ({self.window})")


class ManualTeacher(Teacher):
    """Hands out the current lesson's task and moves on when the student is good enough at it."""

    kind = "manual"

    def __init__(self, space: TaskSpace, seed: int, params: Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed)
        self.params = parse_params(self.kind, ManualParams, params)
        expected = {*LESSON_STEPS, LAST_PARAMETER}
        if set(space.names) != expected:
            raise ValueError(
                f"the manual curriculum is the book's KUKA lesson plan and needs exactly the parameters "
                f"{sorted(expected)}; this space has {sorted(space.names)}"
            )
        start = space.easiest() if self.params.start is None else in_space("start", self.params.start, space)
        self.lessons = lesson_plan(start, space.hardest())
        self.lesson = 0
        self.lesson_rewards: deque[float] = deque(maxlen=self.params.window)
        self.lesson_episodes = 0
        self.stale_results = 0
        self.advanced_at: list[int] = []

    @property
    def current(self) -> Task:
        return self.lessons[self.lesson]

    def _draw(self, first_index: int, count: int) -> list[Task]:
        return [dict(self.current) for _ in range(count)]

    def _learn(self, result: EpisodeResult) -> FitJob | None:
        if not self._is_current(result.task):
            self.stale_results += 1
            return None
        self.lesson_rewards.append(result.reward)
        self.lesson_episodes += 1
        if (
            self.lesson + 1 < len(self.lessons)
            and len(self.lesson_rewards) >= self.params.min_episodes
            and statistics.fmean(self.lesson_rewards) > self.params.threshold
        ):
            self.lesson += 1
            self.lesson_rewards.clear()
            self.lesson_episodes = 0
            self.advanced_at.append(self.results_seen)
        return None

    def _is_current(self, task: Task) -> bool:
        """Results of tasks handed out before the last advance still arrive; they say nothing
        about the new lesson."""
        return all(math.isclose(task[name], value, rel_tol=0.0, abs_tol=SNAP) for name, value in self.current.items())

    def _describe(self) -> dict[str, Any]:
        return {
            "lesson": self.lesson,
            "lessons": len(self.lessons),
            "lesson_params": dict(self.current),
            "final_lesson": self.lesson == len(self.lessons) - 1,
            "lesson_episodes": self.lesson_episodes,
            "recent_mean_reward": statistics.fmean(self.lesson_rewards) if self.lesson_rewards else None,
            "stale_results": self.stale_results,
            "advanced_at_results": list(self.advanced_at),
        }

    def _export(self) -> dict[str, Any]:
        return {
            "lesson": self.lesson,
            "lesson_rewards": list(self.lesson_rewards),
            "lesson_episodes": self.lesson_episodes,
            "stale_results": self.stale_results,
            "advanced_at": list(self.advanced_at),
        }

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        lesson = int(state["lesson"])
        if not 0 <= lesson < len(self.lessons):
            raise ValueError(f"lesson {lesson} is not in this plan of {len(self.lessons)} lessons")
        self.lesson = lesson
        self.lesson_rewards.extend(float(reward) for reward in state["lesson_rewards"])
        self.lesson_episodes = int(state["lesson_episodes"])
        self.stale_results = int(state["stale_results"])
        self.advanced_at = [int(count) for count in state["advanced_at"]]
