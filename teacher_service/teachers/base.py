"""The interface every teacher implements.

Teachers are pure: no I/O, no threads, no clocks. Everything random comes from generators keyed
by the teacher's seed and a counter, so replaying the same results and sample counts rebuilds the
same teacher exactly. Expensive model fits are split out as ``FitJob`` objects so a service can
run them off its request path and ``install`` the result later; so are rebuilds of search
structures (``BuildJob``), which a teacher adopts at a fixed result count whoever ran them.

Saving and restoring a teacher: ``snapshot()`` exports its state as JSON-ready data (counters,
the installed model, per-task bookkeeping; no generator objects, since draws are addressed by
counters), and ``history(start)`` the rows of its append-only history from ``start`` on (float64,
kept out of the snapshot so that saving one does not rewrite the whole history). A fresh teacher
of the same kind, space, seed and params given both by ``restore`` is the same teacher: fed the
same results, it draws the same tasks. ``export_fit``/``import_fit`` turn a fit's output into
plain data and back, so a stored fit is installed without running it again, and ``refit_job``
rebuilds the job of a fit that was due but never finished.

Rebuilding a teacher from its results instead: create it with the same kind, space, seed and
params (or restore a snapshot), then for each later stored result in order call ``skip(n)`` with
the number of tasks handed out before it, followed by ``learn_and_fit(result)``; finish with ``skip`` for
the tasks handed out since the last result. The next ``sample`` then returns what the live teacher
would have returned, except that a live service may have sampled a few tasks before a due fit was
installed, where the replay installs it at once.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from common.client.task_space import ParameterType, Task, TaskSpace
from teacher_service.teachers.params import TeacherParams
from teacher_service.teachers.row_log import RowLog
from teacher_service.teachers.state import StateField, export_fields, import_fields


@dataclass(frozen=True)
class EpisodeResult:
    """One finished episode as a teacher sees it."""

    task: Task
    reward: float
    success: bool | None = None
    length: int | None = None
    score: float | None = None
    """The learner's measure of what the episode has left to teach (robust PLR's positive value loss, or the
    PLR paper's value_l1), when it sends one; the level kinds read it, the rest ignore it."""

    def __post_init__(self) -> None:
        if not math.isfinite(self.reward):
            raise ValueError(f"reward must be finite, got {self.reward}")
        if self.score is not None and not math.isfinite(self.score):
            raise ValueError(f"score must be finite, got {self.score}")


@dataclass(frozen=True)
class FitJob:
    """A model fit that fell due. ``run()`` is pure and may run on any thread; pass its output to
    ``Teacher.install``, in the order the jobs were returned; a failed one is simply left out."""

    index: int
    run: Callable[[], Any]


@dataclass(frozen=True)
class BuildJob:
    """A rebuild of a search structure that the teacher switches to once it has seen
    ``needed_at`` results. ``run()`` is pure and spends its time outside the GIL, so a service runs
    it on a thread and hands the output to ``Teacher.adopt_build``; a teacher that reaches
    ``needed_at`` without it runs the job itself, so the answers never depend on timing."""

    needed_at: int
    run: Callable[[], Any]


def parameter_type_problem(kind: str, accepted: frozenset[ParameterType], space: TaskSpace) -> str | None:
    """Why a kind cannot teach ``space``, naming the first parameter of a type it does not take; None
    when it can."""
    for parameter in space.parameters:
        if parameter.type not in accepted:
            takes = " and ".join(sorted(accepted))
            return (
                f"parameter {parameter.name!r} is {'an' if parameter.type == 'integer' else 'a'} {parameter.type} "
                "parameter: "
                f"the {kind} teacher takes {takes} parameters only"
            )
    return None


class Teacher(ABC):
    """Hands out tasks in a task space and learns from episode results.

    Subclasses implement ``_draw`` (tasks for a run of sample indices), ``_learn_validated`` (one
    result whose task ``learn`` has checked) and ``_describe`` (their part of ``state``), and declare
    their ``state_fields`` for snapshots; this class keeps the counters and checks the input, so every
    kind counts and rejects bad input the same way.

    Learning comes in two forms: ``learn`` records a result and hands back the fit it made due, for
    a service to run elsewhere and ``install`` later; ``learn_and_fit`` runs that fit on the spot
    (tests, tools and offline replays).
    """

    kind: str
    parameter_types: ClassVar[frozenset[ParameterType]] = frozenset({"float"})
    """The task parameter types this kind can teach: a box's teachers model float parameters only."""
    Params: ClassVar[type[TeacherParams]]
    """The kind's parameter model: typed, bounded, documented (``params.TeacherParams``)."""
    params: TeacherParams
    state_fields: ClassVar[tuple[StateField, ...]] = ()
    """The kind's state beyond the counters, as ``snapshot`` stores it (see ``state``); a kind
    whose draws depend on the seed and the counters alone has none."""

    def __init__(self, space: TaskSpace, seed: int, params: TeacherParams | Mapping[str, Any] | None = None) -> None:
        """``params`` may be the kind's model, a mapping of name to value, or ``None`` for the defaults."""
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        refused = self.space_problem(space)
        if refused is not None:
            raise ValueError(refused)
        self.space = space
        self.seed = seed
        self.params = self.Params.parse(params)
        self.tasks_drawn = 0
        """Tasks drawn so far, by ``sample`` and ``skip``: the index of the next task (reported and
        stored as ``tasks_sampled``)."""
        self.results_seen = 0

    def sample(self, count: int) -> list[Task]:
        """Draw ``count`` tasks, each inside the space's bounds.

        Task ``i`` (counting every task this teacher ever handed out) depends only on the seed,
        ``i`` and the model installed at the time, never on how the draws were batched."""
        if isinstance(count, bool) or not isinstance(count, int) or count < 0:
            raise ValueError(f"count must be a non-negative integer, got {count!r}")
        tasks = self._draw(self.tasks_drawn, count)
        self.tasks_drawn += count
        return tasks

    def sample_marked(self, count: int) -> tuple[list[Task], list[bool]]:
        """``sample``, and for each task whether its episode is for scoring only: the learner plays it
        and reports its result but leaves its transitions out of the update (robust PLR's new levels)."""
        first_index = self.tasks_drawn
        tasks = self.sample(count)
        return tasks, self._score_only(first_index, count)

    @classmethod
    def space_problem(cls, space: TaskSpace) -> str | None:
        """Why this kind cannot teach ``space`` (naming the parameter or the limit), else None; the
        service refuses such a curriculum with a 422 before storing anything."""
        return parameter_type_problem(cls.kind, cls.parameter_types, space)

    def skip(self, count: int) -> None:
        """Move past ``count`` tasks handed out before a restart, so the next ``sample`` continues
        where the live teacher stopped. The tasks are redrawn and dropped rather than just counted,
        so per-task bookkeeping (such as ALP-GMM's origin tallies) matches the live run."""
        self.sample(count)

    def learn(self, result: EpisodeResult) -> FitJob | None:
        """Learn from one result; return a fit job when a refit falls due, else ``None``.

        Raises ``ValueError`` when the result's task is not a valid task of this space."""
        task = self.space.validate(result.task)
        self.results_seen += 1
        return self._learn_validated(dataclasses.replace(result, task=task))

    def install(self, fitted: Any) -> None:
        """Adopt the output of a ``FitJob.run()``. Teachers without models have no jobs."""
        raise RuntimeError(f"{self.kind} teacher has no model to install")

    def export_fit(self, fitted: Any) -> dict[str, Any]:
        """A fit's output as JSON-ready data, exact to the bit, for ``import_fit``."""
        raise RuntimeError(f"{self.kind} teacher has no model to export")

    def import_fit(self, data: Mapping[str, Any]) -> Any:
        """The fit output that ``export_fit`` turned into ``data``, ready for ``install``."""
        raise RuntimeError(f"{self.kind} teacher has no model to import")

    def refit_job(self, index: int) -> FitJob:
        """The job ``learn`` returned for fit ``index``, built again from the teacher's history
        (for a fit that fell due before a snapshot and was lost with the process)."""
        raise RuntimeError(f"{self.kind} teacher has no fits")

    def build_job(self) -> BuildJob | None:
        """The pending search-structure rebuild, handed out once; ``None`` when there is none."""
        return None

    def adopt_build(self, job: BuildJob, output: Any) -> None:
        """Keep the output of ``job.run()`` for when the teacher reaches ``job.needed_at``; the
        output of a job the teacher no longer waits for is dropped."""
        raise RuntimeError(f"{self.kind} teacher has no builds")

    def snapshot(self) -> dict[str, Any]:
        """Everything but the history, as JSON-ready data; ``restore`` reads it back."""
        return {
            "kind": self.kind,
            "tasks_sampled": self.tasks_drawn,
            "results_seen": self.results_seen,
            "state": self._export(),
        }

    def _history_rows(self) -> RowLog | None:
        """The append-only history, for kinds that keep one: one float64 row per result, which
        never changes once written, so a store can append the rows in chunks."""
        return None

    @property
    def history_size(self) -> int:
        """Rows in the append-only history (see ``history``)."""
        rows = self._history_rows()
        return 0 if rows is None else rows.size

    def history(self, start: int) -> np.ndarray:
        """History rows ``start`` onwards, shape (rows, width); what a row holds is the kind's own
        (see its ``_history_rows``)."""
        rows = self._history_rows()
        return np.empty((0, 0)) if rows is None else rows.copy(start)

    @property
    def history_held(self) -> int:
        """History rows still in memory (the rest were released and are no longer read)."""
        rows = self._history_rows()
        return 0 if rows is None else rows.held

    def release_history(self, before: int) -> None:
        """History rows before ``before`` are stored and will not be asked for again: a teacher
        drops those its algorithm no longer reads, so its memory stays bounded."""
        rows = self._history_rows()
        if rows is not None:
            rows.release(before)

    @staticmethod
    def history_kept_from(snapshot: Mapping[str, Any]) -> int:
        """The first history row that ``restore`` needs with ``snapshot`` (rows before it were
        dropped from memory by then, and are not needed again)."""
        return int(snapshot["state"].get("history_from", 0))

    def restore(self, snapshot: Mapping[str, Any], history: np.ndarray) -> None:
        """Become the teacher that ``snapshot()`` described, with ``history`` its rows from
        ``history_kept_from(snapshot)`` up to then. Only on a fresh teacher built with the same
        kind, space, seed and params."""
        if snapshot["kind"] != self.kind:
            raise ValueError(f"a {snapshot['kind']} snapshot cannot restore a {self.kind} teacher")
        if self.tasks_drawn or self.results_seen:
            raise RuntimeError("restore needs a fresh teacher")
        self._import(snapshot["state"], history)
        self.tasks_drawn = int(snapshot["tasks_sampled"])
        self.results_seen = int(snapshot["results_seen"])

    def learn_and_fit(self, result: EpisodeResult) -> None:
        """Learn from a result and run any fit it makes due right here (for tests and tools)."""
        job = self.learn(result)
        if job is not None:
            self.install(job.run())

    def state(self) -> dict[str, Any]:
        """JSON-ready description of the teacher for the dashboard."""
        return {
            "kind": self.kind,
            "seed": self.seed,
            "params": self.params.model_dump(),
            "tasks_sampled": self.tasks_drawn,
            "results_seen": self.results_seen,
            **self._describe(),
        }

    @abstractmethod
    def _draw(self, first_index: int, count: int) -> list[Task]:
        """Tasks number ``first_index`` to ``first_index + count - 1``."""

    def _score_only(self, first_index: int, count: int) -> list[bool]:
        """Which of the tasks just drawn (``first_index`` on) are for scoring only; none, but for
        robust PLR."""
        return [False] * count

    @abstractmethod
    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        """The kind's own learning from a result whose task ``learn`` has validated and counted."""

    @abstractmethod
    def _describe(self) -> dict[str, Any]:
        """The kind's own JSON-ready state entries."""

    def _export(self) -> dict[str, Any]:
        """The kind's own state beyond the counters, JSON-ready, for ``snapshot``: its
        ``state_fields``; a kind with state no codec fits adds it here (``state``)."""
        return export_fields(self, self.state_fields)

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        """Adopt what ``_export`` returned, and the history rows up to it."""
        import_fields(self, self.state_fields, state)
