"""A live curriculum: one teacher over one task space, its bookkeeping (tasks out, results in,
counters), and the fits, builds and snapshots it needs. (A service's set of them is ``registry``.)

Threading model: a teacher is only ever touched on the event loop thread. Requests sample from it
and the store's commit callbacks feed it results, both on the loop; a due fit runs in the fit
process as a pure job, and its output comes back to the loop to be installed; a due rebuild of a
teacher's search structure (``BuildJob``) runs on a thread, since it holds no GIL, and its output
comes back to the loop too. So no teacher needs a lock, sampling always uses the last installed
model, and neither a refit nor a rebuild holds up a request.

Every ``snapshot_every`` results, once those results are committed, a curriculum stores a
snapshot: the teacher's exported state, the new rows of its history, its counters and outstanding
tasks, and the fits that were due and not back; a restart starts from it (``replay``). The
snapshot goes into the group commit after the results it follows: the teacher learns only
committed results, so its state after them exists only then; a crash between the two costs
nothing but a longer replay from the previous snapshot.

Three counts of tasks, which differ: ``Curriculum.tasks_issued`` counts the tasks handed out (on
disk); ``Curriculum.issued_index_end`` is one past the highest task index on disk, above
``tasks_issued`` when a write of drawn tasks failed; and the teacher's ``tasks_drawn`` counts its
draws, including tasks whose write is in flight or failed (the index of its next task).
"""

from __future__ import annotations

import asyncio
import functools
import json
import logging
import time
from collections import deque
from concurrent.futures import Executor
from typing import Any

from common.client.schemas import FitEvent, IssuedTask, RecentResult, ResultAck, ResultItem
from common.client.task_space import Task
from teacher_service.core.config import Settings
from teacher_service.curriculum_spec import TypedSpec
from teacher_service.fits import FitOutcome, FitRunner
from teacher_service.metrics import RateCounter, ServiceMetrics
from teacher_service.replay import Replayed
from teacher_service.store import NewResult, NewTask, Store, StoredFit, TeacherSnapshot
from teacher_service.teachers import BuildJob, EpisodeResult, FitJob, Teacher, make_teacher

log = logging.getLogger(__name__)

FIT_HISTORY = 200
"""Fit events kept per curriculum for ``/state``."""


class UnknownCurriculum(KeyError):
    """No curriculum has this name."""


class CurriculumConflict(Exception):
    """The name is taken by a curriculum with a different configuration."""


class InvalidResults(ValueError):
    """Some result items cannot be applied; ``errors`` are FastAPI-style validation errors."""

    def __init__(self, errors: list[dict[str, Any]]) -> None:
        super().__init__(f"{len(errors)} invalid result(s)")
        self.errors = errors


class Curriculum:
    """One named teacher over one task space, with the bookkeeping the API reports."""

    def __init__(
        self,
        curriculum_id: int,
        name: str,
        spec: TypedSpec,
        created_at: float,
        store: Store,
        fits: FitRunner,
        builds: Executor,
        metrics: ServiceMetrics,
        settings: Settings,
    ) -> None:
        self.id = curriculum_id
        self.name = name
        self.spec = spec
        self.config = spec.to_client_spec()
        self.space = spec.task_space()
        self.teacher: Teacher = make_teacher(spec.teacher, self.space, spec.seed, spec.params)
        self.created_at = created_at
        self.tasks_issued = 0
        """Tasks handed out: drawn and on disk."""
        self.issued_index_end = 0
        """One past the highest task index on disk: task ids below it have been handed out (or
        were drawn for a write that failed)."""
        self.results_received = 0
        self.outstanding: dict[int, Task] = {}
        """Tasks awaiting a result, by index."""
        self.tasks_expired = 0
        self._awaiting: deque[tuple[int, float, int]] = deque()
        """(index, issued_at, ordinal) of the tasks that may still be outstanding, oldest first; the
        ordinal counts stored tasks, so the task window ignores indices drawn for a failed write."""
        self._writing: dict[int, asyncio.Future[None]] = {}
        """Tasks whose result is being stored, each with a future that settles once that write has
        committed or failed: a second result for one waits for it (see ``report``)."""
        self._task_ttl_s = settings.task_ttl_s
        self._task_window = settings.task_window
        self.recent_results: deque[RecentResult] = deque(maxlen=settings.recent_results)
        self.fit_events: deque[FitEvent] = deque(maxlen=FIT_HISTORY)
        self.fits_completed = 0
        self.fits_pending = 0
        self.last_fit_at: float | None = None
        self._store = store
        self._fits = fits
        self._builds = builds
        self._fits_waiting: set[int] = set()
        """Fits submitted whose outcome has not come back; a snapshot lists them."""
        self._lost_fits: list[FitJob] = []
        """Fits a restart found due and never recorded; they run once the service has started."""
        self._last_result_index: int | None = None
        self._snapshot_every = settings.snapshot_every
        self._snapshot_at = 0
        """Results learned at the last stored snapshot."""
        self._history_stored = 0
        self._snapshot_queued = False
        self._metrics = metrics.for_curriculum(name)
        self._result_rate = RateCounter(settings.rate_window_s, since=time.time())

    def task_id(self, index: int) -> str:
        return f"{self.name}:{index}"

    def task_index(self, task_id: str) -> int | None:
        """The index behind one of this curriculum's issued task ids, else ``None``."""
        name, _, digits = task_id.rpartition(":")
        if name != self.name or not (digits.isascii() and digits.isdigit()) or digits != str(int(digits)):
            return None
        index = int(digits)
        return index if index < self.issued_index_end else None

    async def issue(self, count: int) -> list[IssuedTask]:
        """Draw tasks and answer once they are on disk."""
        first = self.teacher.tasks_drawn
        results_seen = self.teacher.results_seen
        drawn, score_only = self.teacher.sample_marked(count)
        tasks = [self.space.validate(task) for task in drawn]
        issued_at = time.time()
        records = [NewTask(first + i, task, results_seen, issued_at) for i, task in enumerate(tasks)]

        def stored() -> None:
            self.outstanding.update(zip(range(first, first + count), tasks, strict=True))
            self._awaiting.extend((first + i, issued_at, self.tasks_issued + i) for i in range(count))
            self.tasks_issued += count
            self.issued_index_end = max(self.issued_index_end, first + count)
            self._metrics.tasks_issued.inc(count)
            self._expire(issued_at)

        await self._store.add_tasks(self.id, records, on_commit=stored)
        return [
            IssuedTask(task_id=self.task_id(first + i), params=task, score_only=only)
            for i, (task, only) in enumerate(zip(tasks, score_only, strict=True))
        ]

    async def report(self, items: list[ResultItem]) -> ResultAck:
        """Store new results, then learn from them; all or nothing.

        A result for a task that already has one (or appears twice here) is a duplicate, and one for
        a task that expired is late; both are ignored and counted, which makes retries safe. Results
        are claimed before the write so a concurrent request cannot apply the same task twice. A
        result whose task another request is still storing waits for that write: acknowledged as a
        duplicate once it has committed, claimed here if it failed. (Acknowledging it at once would lose
        it when a client's retry is told "duplicate" and the write it duplicated then meets a full disk.)
        """
        indices = self._known_indices(items)
        while in_flight := {self._writing[index] for index in indices if index in self._writing}:
            await asyncio.wait(in_flight)  # a cancelled request leaves the write alone
        received_at = time.time()
        self._expire(received_at)
        claimed: dict[int, ResultItem] = {}
        settled: list[int] = []
        duplicates = 0
        for index, item in zip(indices, items, strict=True):
            if index in claimed:
                duplicates += 1
            elif index in self.outstanding:
                claimed[index] = item
            else:
                settled.append(index)
        answered = self._store.answered_tasks(self.id, settled) if settled else set()
        late_duplicates = sum(index in answered for index in settled)
        duplicates += late_duplicates
        expired = len(settled) - late_duplicates
        self._metrics.results_duplicate.inc(duplicates)
        self._metrics.results_expired.inc(expired)
        ack = ResultAck(accepted=len(claimed), duplicates=duplicates, expired=expired)
        if not claimed:
            return ack
        tasks = {index: self.outstanding[index] for index in claimed}
        write_settled = asyncio.get_running_loop().create_future()
        self._writing.update(dict.fromkeys(claimed, write_settled))
        records = [
            NewResult(index, item.reward, item.success, item.length, received_at, item.score)
            for index, item in claimed.items()
        ]

        def release() -> None:
            for index in claimed:
                del self._writing[index]
            write_settled.set_result(None)

        def stored() -> None:
            release()
            for index, item in claimed.items():
                self.outstanding.pop(index, None)
                job = self._apply_result(
                    index, EpisodeResult(tasks[index], item.reward, item.success, item.length, item.score)
                )
                self.recent_results.append(
                    RecentResult(
                        task_id=self.task_id(index),
                        params=tasks[index],
                        reward=item.reward,
                        success=item.success,
                        length=item.length,
                        received_at=received_at,
                        score=item.score,
                    )
                )
                if job is not None:
                    self._submit_fit(job, replayed=False)
            self._start_build()
            self._snapshot_if_due()
            self._result_rate.count(received_at, len(claimed))
            self._metrics.results_accepted.inc(len(claimed))

        await self._store.add_results(self.id, records, on_commit=stored, on_abort=release)
        return ack

    def _known_indices(self, items: list[ResultItem]) -> list[int]:
        """The task index of each result; ``InvalidResults`` naming every id this curriculum never issued."""
        indices = [self.task_index(item.task_id) for item in items]
        errors = [
            {
                "loc": ["body", "results", position, "task_id"],
                "msg": f"unknown task id {item.task_id!r}: curriculum {self.name!r} never issued it",
                "type": "unknown_task",
                "input": item.task_id,
            }
            for position, (item, index) in enumerate(zip(items, indices, strict=True))
            if index is None
        ]
        if errors:
            raise InvalidResults(errors)
        return [index for index in indices if index is not None]

    def _expire(self, now: float) -> None:
        """Forget tasks handed out more than ``task_ttl_s`` ago or ``task_window`` tasks ago. The
        window counts tasks handed out, not indices: every draw a full disk refused took indices too,
        and counting those would expire the tasks whose results wait for the disk to have room."""
        deadline, oldest_kept = now - self._task_ttl_s, self.tasks_issued - self._task_window
        expired = 0
        while self._awaiting and (self._awaiting[0][2] < oldest_kept or self._awaiting[0][1] < deadline):
            index, _, _ = self._awaiting.popleft()
            if self.outstanding.pop(index, None) is not None and index not in self._writing:
                expired += 1
        if expired:
            self.tasks_expired += expired
            self._metrics.tasks_expired.inc(expired)

    def _apply_result(self, index: int, result: EpisodeResult) -> FitJob | None:
        """Teach the teacher one committed result and count it; returns the fit it made due."""
        job = self.teacher.learn(result)
        self.results_received += 1
        self._last_result_index = index
        return job

    def _submit_fit(self, job: FitJob, replayed: bool) -> None:
        self.fits_pending += 1
        self._metrics.fits_pending.inc()
        self._fits_waiting.add(job.index)
        self._fits.submit(self.name, job, functools.partial(self._install_live, replayed=replayed))

    def _install_live(self, outcome: FitOutcome, replayed: bool) -> None:
        self.fits_pending -= 1
        self._metrics.fits_pending.dec()
        self._fits_waiting.discard(outcome.index)
        error = self._install(outcome, replayed)
        self._store.add_fit_later(self.id, self._fit_record(outcome, error))

    def _install(self, outcome: FitOutcome, replayed: bool) -> str | None:
        """Adopt a fit's model; a failed fit or install is recorded and the previous model stays.
        Returns the error, if any."""
        error = outcome.error
        if error is None:
            try:
                self.teacher.install(outcome.output)
            except Exception as exception:
                log.exception("curriculum %r: installing fit %d failed", self.name, outcome.index)
                error = f"install failed: {type(exception).__name__}: {exception}"
        if error is None:
            self._metrics.fits.inc()
            self._metrics.fit_seconds.observe(outcome.finished_at - outcome.started_at)
        else:
            self._metrics.fit_errors.inc()
        self.fits_completed += 1
        self.last_fit_at = outcome.finished_at
        self.fit_events.append(_fit_event(outcome.index, outcome.started_at, outcome.finished_at, replayed, error))
        return error

    def _fit_record(self, outcome: FitOutcome, error: str | None) -> StoredFit:
        model = None if error is not None else json.dumps(self.teacher.export_fit(outcome.output))
        return StoredFit(
            index=outcome.index,
            tasks_drawn=self.teacher.tasks_drawn,
            results_seen=self.teacher.results_seen,
            started_at=outcome.started_at,
            finished_at=outcome.finished_at,
            error=error,
            model=model,
        )

    def _start_build(self) -> None:
        """Run the teacher's due search-structure rebuild on a thread; the output comes back to the loop."""
        job = self.teacher.build_job()
        if job is not None:
            future = asyncio.get_running_loop().run_in_executor(self._builds, job.run)
            future.add_done_callback(functools.partial(self._adopt_build, job))

    def _adopt_build(self, job: BuildJob, future: asyncio.Future[Any]) -> None:
        if future.cancelled():
            return
        if (error := future.exception()) is not None:
            log.error("curriculum %r: a background build failed (%r); the teacher builds it when due", self.name, error)
            return
        self.teacher.adopt_build(job, future.result())

    def _snapshot_if_due(self) -> None:
        if self._snapshot_queued or self.teacher.results_seen - self._snapshot_at < self._snapshot_every:
            return
        snapshot = self._snapshot()
        self._snapshot_queued = True

        def stored() -> None:
            self._snapshot_queued = False
            self._snapshot_at = snapshot.results_seen
            self._history_stored = snapshot.history_from + len(snapshot.history)
            self.teacher.release_history(self._history_stored)

        def not_stored() -> None:
            self._snapshot_queued = False

        self._store.put_snapshot_later(self.id, snapshot, on_commit=stored, on_abort=not_stored)

    def _snapshot(self) -> TeacherSnapshot:
        return TeacherSnapshot(
            results_seen=self.teacher.results_seen,
            last_task_index=self._last_result_index,
            tasks_issued=self.tasks_issued,
            issued_index_end=self.issued_index_end,
            outstanding=sorted(self.outstanding),
            fits_waiting=sorted(self._fits_waiting),
            teacher=self.teacher.snapshot(),
            history=self.teacher.history(self._history_stored),
            history_from=self._history_stored,
            taken_at=time.time(),
        )

    def results_per_second(self, now: float) -> float:
        """Results accepted per second over the recent window (``KC_RATE_WINDOW_S``)."""
        return self._result_rate.per_second(now)

    @property
    def fits_stopped(self) -> str | None:
        """Why no fits run any more, if the fit processes kept dying."""
        return self._fits.stopped

    @property
    def writes_failing(self) -> str | None:
        """Why the database refuses writes, while it does (``Store.writes_failing``)."""
        return self._store.writes_failing

    def adopt_replay(self, replayed: Replayed) -> None:
        """Take on what a start-up replay rebuilt (the teacher it rebuilt in place is this
        curriculum's); before the service starts. A start that replayed anything stores a snapshot,
        with the fits it ran again, so the next start replays nothing of it."""
        self.tasks_issued = replayed.tasks_issued
        self.issued_index_end = replayed.issued_index_end
        self.results_received = self.teacher.results_seen
        self._last_result_index = replayed.last_result_index
        self._snapshot_at, self._history_stored = replayed.snapshot_at, replayed.history_stored
        for awaited, ordinal in replayed.awaited:
            self.outstanding[awaited.index] = awaited.task
            self._awaiting.append((awaited.index, awaited.issued_at, ordinal))
        self._expire(time.time())
        for job in replayed.lost_fits:
            self._lost_fits.append(job)
            self._fits_waiting.add(job.index)
        for fit in replayed.recent_fits:
            self.fit_events.append(_fit_event(fit.index, fit.started_at, fit.finished_at, True, fit.error))
        self.fits_completed = replayed.fits_completed
        self.last_fit_at = self.fit_events[-1].finished_at if self.fit_events else None
        for result in replayed.recent_results:
            self.recent_results.append(
                RecentResult(
                    task_id=self.task_id(result.task_index),
                    params=result.task,
                    reward=result.reward,
                    success=result.success,
                    length=result.length,
                    received_at=result.received_at,
                    score=result.score,
                )
            )
        if replayed.results_replayed or replayed.rerun_fits:
            snapshot = self._snapshot()
            self._store.save_replayed_now(self.id, replayed.rerun_fits, snapshot)
            self._snapshot_at, self._history_stored = snapshot.results_seen, self.teacher.history_size
            self.teacher.release_history(self._history_stored)

    def resume(self) -> None:
        """Hand the fits a restart lost, and a pending rebuild, to the background; on the event loop."""
        for job in self._lost_fits:
            self._fits_waiting.discard(job.index)
            self._submit_fit(job, replayed=True)
        self._lost_fits.clear()
        self._start_build()


def _fit_event(index: int, started_at: float, finished_at: float, replayed: bool, error: str | None) -> FitEvent:
    return FitEvent(
        index=index,
        started_at=started_at,
        finished_at=finished_at,
        duration_s=finished_at - started_at,
        replayed=replayed,
        error=error,
    )
