"""The interface every teacher implements.

Teachers are pure: no I/O, no threads, no clocks. Everything random comes from generators keyed
by the teacher's seed and a counter, so replaying the same results and sample counts rebuilds the
same teacher exactly. Expensive model fits are split out as ``FitJob`` objects so a service can
run them off its request path and ``install`` the result later.

Rebuilding a teacher from its history: create it with the same kind, space, seed and params, then
for each stored result in order call ``skip(n)`` with the number of tasks handed out before it,
followed by ``observe(result)``; finish with ``skip`` for the tasks handed out since the last
result. The next ``sample`` then returns what the live teacher would have returned, except that a
live service may have sampled a few tasks before a due fit was installed, where the replay
installs it at once.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from common.task_space import Task, TaskSpace
from teacher_service.teachers.params import TeacherParams


@dataclass(frozen=True)
class EpisodeResult:
    """One finished episode as a teacher sees it."""

    task: Task
    reward: float
    success: bool | None = None
    length: int | None = None

    def __post_init__(self) -> None:
        if not math.isfinite(self.reward):
            raise ValueError(f"reward must be finite, got {self.reward}")


@dataclass(frozen=True)
class FitJob:
    """A model fit that fell due. ``run()`` is pure and may run on any thread; pass its output to
    ``Teacher.install``, in the order the jobs were returned; a failed one is simply left out."""

    index: int
    run: Callable[[], Any]


class Teacher(ABC):
    """Hands out tasks in a task space and learns from episode results.

    Subclasses implement ``_draw`` (tasks for a run of sample indices), ``_learn`` (one validated
    result) and ``_describe`` (their part of ``state``); this class keeps the counters and checks
    the input, so every kind counts and rejects bad input the same way.
    """

    kind: str
    Params: ClassVar[type[TeacherParams]]
    """The kind's parameter model: typed, bounded, documented (``params.TeacherParams``)."""
    params: TeacherParams

    def __init__(self, space: TaskSpace, seed: int, params: TeacherParams | Mapping[str, Any] | None = None) -> None:
        """``params`` may be the kind's model, a mapping of name to value, or ``None`` for the defaults."""
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        self.space = space
        self.seed = seed
        self.params = self.Params.parse(params)
        self.tasks_sampled = 0
        self.results_seen = 0

    def sample(self, count: int) -> list[Task]:
        """Draw ``count`` tasks, each inside the space's bounds.

        Task ``i`` (counting every task this teacher ever handed out) depends only on the seed,
        ``i`` and the model installed at the time, never on how the draws were batched."""
        if isinstance(count, bool) or not isinstance(count, int) or count < 0:
            raise ValueError(f"count must be a non-negative integer, got {count!r}")
        tasks = self._draw(self.tasks_sampled, count)
        self.tasks_sampled += count
        return tasks

    def skip(self, count: int) -> None:
        """Move past ``count`` tasks handed out before a restart, so the next ``sample`` continues
        where the live teacher stopped. The tasks are redrawn and dropped rather than just counted,
        so per-task bookkeeping (such as ALP-GMM's origin tallies) matches the live run."""
        self.sample(count)

    def update(self, result: EpisodeResult) -> FitJob | None:
        """Record one result; return a fit job when a refit falls due, else ``None``.

        Raises ``ValueError`` when the result's task is not a valid task of this space."""
        task = self.space.validate(result.task)
        self.results_seen += 1
        return self._learn(dataclasses.replace(result, task=task))

    def install(self, fitted: Any) -> None:
        """Adopt the output of a ``FitJob.run()``. Teachers without models have no jobs."""
        raise RuntimeError(f"{self.kind} teacher has no model to install")

    def observe(self, result: EpisodeResult) -> None:
        """Record a result and run any fit it triggers right here (for tests and replays)."""
        job = self.update(result)
        if job is not None:
            self.install(job.run())

    def state(self) -> dict[str, Any]:
        """JSON-ready description of the teacher for the dashboard."""
        return {
            "kind": self.kind,
            "seed": self.seed,
            "params": self.params.model_dump(),
            "tasks_sampled": self.tasks_sampled,
            "results_seen": self.results_seen,
            **self._describe(),
        }

    @abstractmethod
    def _draw(self, first_index: int, count: int) -> list[Task]:
        """Tasks number ``first_index`` to ``first_index + count - 1``."""

    @abstractmethod
    def _learn(self, result: EpisodeResult) -> FitJob | None:
        """Learn from a result whose task has been validated."""

    @abstractmethod
    def _describe(self) -> dict[str, Any]:
        """The kind's own JSON-ready state entries."""
