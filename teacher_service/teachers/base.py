"""The interface every teacher implements.

Teachers are pure: no I/O, no threads, no clocks. Everything random comes from generators keyed
by the teacher's seed and a counter, so replaying the same results and sample counts rebuilds the
same teacher exactly. Expensive model fits are split out as ``FitJob`` objects so a service can
run them off its request path and ``install`` the result later.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from common.task_space import Task, TaskSpace


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
    ``Teacher.install``. Jobs must be installed in the order they were returned."""

    index: int
    run: Callable[[], Any]


class Teacher(ABC):
    """Hands out tasks in a task space and learns from episode results."""

    kind: str

    def __init__(self, space: TaskSpace, seed: int) -> None:
        self.space = space
        self.seed = int(seed)
        self.tasks_sampled = 0
        self.results_seen = 0

    @abstractmethod
    def sample(self, count: int) -> list[Task]:
        """Draw ``count`` tasks, each inside the space's bounds."""

    @abstractmethod
    def update(self, result: EpisodeResult) -> FitJob | None:
        """Record one result; return a fit job when a refit falls due, else ``None``."""

    def install(self, fitted: Any) -> None:
        """Adopt the output of a ``FitJob.run()``. Teachers without models have no jobs."""
        raise RuntimeError(f"{self.kind} teacher has no model to install")

    @abstractmethod
    def state(self) -> dict[str, Any]:
        """JSON-ready description of the teacher for the dashboard."""

    def observe(self, result: EpisodeResult) -> None:
        """Record a result and run any fit it triggers right here (for tests and replays)."""
        job = self.update(result)
        if job is not None:
            self.install(job.run())


TeacherFactory = Callable[[TaskSpace, int, Mapping[str, Any]], Teacher]
