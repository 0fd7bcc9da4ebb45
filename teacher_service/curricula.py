"""The live curricula: one teacher each, its counters, and the fits it needs.

Threading model: a teacher is only ever touched on the event loop thread. Requests sample from it
and the store's commit callbacks feed it results, both on the loop; a due fit runs in the fit
process as a pure job, and its output comes back to the loop to be installed; a due rebuild of a
teacher's search structure (``BuildJob``) runs on a thread, since it holds no GIL, and its output
comes back to the loop too. So no teacher needs a lock, sampling always uses the last installed
model, and neither a refit nor a rebuild holds up a request.

What is stored lets a restart rebuild the exact live state in bounded time. Each task row carries
how many results the teacher had learned from when it was drawn, and each fit row how many tasks
and results it had seen when it was installed, and the fitted model. Every ``snapshot_every``
results, once those results are committed, the curriculum stores a snapshot: the teacher's
exported state, the new rows of its history, its counters and outstanding tasks, and the fits
that were due and not back. A restart restores the newest snapshot, then replays only the results
stored after it, in order, drawing (and dropping) tasks and installing fits from their stored
models at the same points; so the rebuilt teacher has the same model, counters and per-task
bookkeeping, and draws the same next tasks, and no installed fit is ever run again. A fit that
was due but never recorded (the process died first) runs again once, through the fit process,
as it would have live. The snapshot goes into the group commit after the results it follows: the
teacher learns only committed results, so its state after them exists only then; a crash between
the two costs nothing but a longer replay from the previous snapshot. The first start on a
database without snapshots (schema version 1) replays everything and runs the fits whose models
were never stored, then stores a snapshot, as every start that replayed anything does.
"""

from __future__ import annotations

import asyncio
import functools
import json
import logging
import time
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, ThreadPoolExecutor
from typing import Any

from tqdm import tqdm

from common.schemas import (
    CurriculumCounters,
    CurriculumInfo,
    CurriculumState,
    FitEvent,
    IssuedTask,
    RecentResult,
    ResultAck,
    ResultItem,
)
from common.task_space import Task
from teacher_service.core.config import Settings
from teacher_service.curriculum_spec import TypedSpec, stored_spec
from teacher_service.fits import FitOutcome, FitRunner, run_fit
from teacher_service.metrics import ServiceMetrics
from teacher_service.store import (
    INSERT_CURRICULUM,
    INSERT_FIT,
    INSERT_RESULT,
    INSERT_TASK,
    Store,
    StoredCurriculum,
    StoredFit,
    StoredTask,
    TeacherSnapshot,
    snapshot_statements,
)
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
        self.issued_through = 0
        """One past the highest task index on disk: task ids below it have been handed out."""
        self.results_received = 0
        self.outstanding: dict[int, Task] = {}
        """Tasks awaiting a result, by index."""
        self.tasks_expired = 0
        self._awaiting: deque[tuple[int, float]] = deque()
        """(index, issued_at) of the tasks that may still be outstanding, oldest first."""
        self._writing: set[int] = set()
        """Tasks whose result is being stored: a second result for one is a duplicate."""
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
        self._tasks_counter = metrics.tasks_issued.labels(name)
        self._expired_tasks_counter = metrics.tasks_expired.labels(name)
        self._expired_results_counter = metrics.results.labels(name, "expired")
        self._accepted_counter = metrics.results.labels(name, "accepted")
        self._duplicate_counter = metrics.results.labels(name, "duplicate")
        self._fits_counter = metrics.fits.labels(name)
        self._fit_errors_counter = metrics.fit_errors.labels(name)
        self._fit_seconds = metrics.fit_seconds.labels(name)
        self._fits_pending_gauge = metrics.fits_pending.labels(name)
        self._rate_window = settings.rate_window_s
        self._counting_since = time.time()
        self._arrivals: deque[tuple[float, int]] = deque()

    def task_id(self, index: int) -> str:
        return f"{self.name}:{index}"

    def task_index(self, task_id: str) -> int | None:
        """The index behind one of this curriculum's issued task ids, else ``None``."""
        name, _, digits = task_id.rpartition(":")
        if name != self.name or not (digits.isascii() and digits.isdigit()) or digits != str(int(digits)):
            return None
        index = int(digits)
        return index if index < self.issued_through else None

    async def issue(self, count: int) -> list[IssuedTask]:
        """Draw tasks and answer once they are on disk."""
        first = self.teacher.tasks_drawn
        results_seen = self.teacher.results_seen
        tasks = [self.space.validate(task) for task in self.teacher.sample(count)]
        issued_at = time.time()
        rows = [(self.id, first + i, json.dumps(task), results_seen, issued_at) for i, task in enumerate(tasks)]

        def stored() -> None:
            self.outstanding.update(zip(range(first, first + count), tasks, strict=True))
            self._awaiting.extend((index, issued_at) for index in range(first, first + count))
            self.tasks_issued += count
            self.issued_through = max(self.issued_through, first + count)
            self._tasks_counter.inc(count)
            self._expire(issued_at)

        await self._store.write([(INSERT_TASK, rows)], on_commit=stored)
        return [IssuedTask(task_id=self.task_id(first + i), params=task) for i, task in enumerate(tasks)]

    async def report(self, items: list[ResultItem]) -> ResultAck:
        """Store new results, then learn from them; all or nothing.

        A result for a task that already has one (or appears twice here) is a duplicate, and one for
        a task that expired is late; both are ignored and counted, which makes retries safe. Results
        are claimed before the write so a concurrent request cannot apply the same task twice.
        """
        received_at = time.time()
        self._expire(received_at)
        errors: list[dict[str, Any]] = []
        claimed: dict[int, ResultItem] = {}
        settled: list[int] = []
        duplicates = 0
        for position, item in enumerate(items):
            index = self.task_index(item.task_id)
            if index is None:
                errors.append(
                    {
                        "loc": ["body", "results", position, "task_id"],
                        "msg": f"unknown task id {item.task_id!r}: curriculum {self.name!r} never issued it",
                        "type": "unknown_task",
                        "input": item.task_id,
                    }
                )
            elif index in claimed or index in self._writing:
                duplicates += 1
            elif index in self.outstanding:
                claimed[index] = item
            else:
                settled.append(index)
        if errors:
            raise InvalidResults(errors)
        answered = self._store.answered_tasks(self.id, settled) if settled else set()
        late_duplicates = sum(index in answered for index in settled)
        duplicates += late_duplicates
        expired = len(settled) - late_duplicates
        self._duplicate_counter.inc(duplicates)
        self._expired_results_counter.inc(expired)
        ack = ResultAck(accepted=len(claimed), duplicates=duplicates, expired=expired)
        if not claimed:
            return ack
        tasks = {index: self.outstanding[index] for index in claimed}
        self._writing.update(claimed)
        rows = [
            (self.id, index, item.reward, item.success, item.length, received_at) for index, item in claimed.items()
        ]

        def stored() -> None:
            self._writing.difference_update(claimed)
            for index, item in claimed.items():
                self.outstanding.pop(index, None)
                job = self._learn(index, tasks[index], item.reward, item.success, item.length)
                self.recent_results.append(
                    RecentResult(
                        task_id=self.task_id(index),
                        params=tasks[index],
                        reward=item.reward,
                        success=item.success,
                        length=item.length,
                        received_at=received_at,
                    )
                )
                if job is not None:
                    self._submit_fit(job, replayed=False)
            self._start_build()
            self._snapshot_if_due()
            self._count_arrivals(received_at, len(claimed))
            self._accepted_counter.inc(len(claimed))

        def not_stored() -> None:
            self._writing.difference_update(claimed)

        await self._store.write([(INSERT_RESULT, rows)], on_commit=stored, on_abort=not_stored)
        return ack

    def _expire(self, now: float) -> None:
        """Forget tasks handed out more than ``task_ttl_s`` ago or ``task_window`` tasks ago."""
        deadline, oldest_kept = now - self._task_ttl_s, self.issued_through - self._task_window
        expired = 0
        while self._awaiting and (self._awaiting[0][0] < oldest_kept or self._awaiting[0][1] < deadline):
            index, _ = self._awaiting.popleft()
            if self.outstanding.pop(index, None) is not None and index not in self._writing:
                expired += 1
        if expired:
            self.tasks_expired += expired
            self._expired_tasks_counter.inc(expired)

    def _learn(self, index: int, task: Task, reward: float, success: bool | None, length: int | None) -> FitJob | None:
        job = self.teacher.learn(EpisodeResult(task, reward, success, length))
        self.results_received += 1
        self._last_result_index = index
        return job

    def _submit_fit(self, job: FitJob, replayed: bool) -> None:
        self.fits_pending += 1
        self._fits_pending_gauge.inc()
        self._fits_waiting.add(job.index)
        self._fits.submit(self.name, job, functools.partial(self._install_live, replayed=replayed))

    def _install_live(self, outcome: FitOutcome, replayed: bool) -> None:
        self.fits_pending -= 1
        self._fits_pending_gauge.dec()
        self._fits_waiting.discard(outcome.index)
        error = self._install(outcome, replayed)
        self._store.write_later([(INSERT_FIT, [self._fit_row(outcome, error)])])

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
            self._fits_counter.inc()
            self._fit_seconds.observe(outcome.finished_at - outcome.started_at)
        else:
            self._fit_errors_counter.inc()
        self.fits_completed += 1
        self.last_fit_at = outcome.finished_at
        self.fit_events.append(_fit_event(outcome.index, outcome.started_at, outcome.finished_at, replayed, error))
        return error

    def _fit_row(self, outcome: FitOutcome, error: str | None) -> tuple[Any, ...]:
        model = None if error is not None else json.dumps(self.teacher.export_fit(outcome.output))
        return (
            self.id,
            outcome.index,
            self.teacher.tasks_drawn,
            self.teacher.results_seen,
            outcome.started_at,
            outcome.finished_at,
            error,
            model,
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

        self._store.write_later(snapshot_statements(self.id, snapshot), on_commit=stored, on_abort=not_stored)

    def _snapshot(self) -> TeacherSnapshot:
        return TeacherSnapshot(
            results_seen=self.teacher.results_seen,
            last_task_index=self._last_result_index,
            tasks_issued=self.tasks_issued,
            issued_through=self.issued_through,
            outstanding=sorted(self.outstanding),
            fits_waiting=sorted(self._fits_waiting),
            teacher=self.teacher.snapshot(),
            history=self.teacher.history(self._history_stored),
            history_from=self._history_stored,
            taken_at=time.time(),
        )

    def _count_arrivals(self, now: float, count: int) -> None:
        self._arrivals.append((now, count))
        while self._arrivals and self._arrivals[0][0] < now - self._rate_window:
            self._arrivals.popleft()

    def results_per_second(self, now: float) -> float:
        recent = sum(count for at, count in self._arrivals if at >= now - self._rate_window)
        return recent / max(min(self._rate_window, now - self._counting_since), 1e-3)

    def info(self) -> CurriculumInfo:
        now = time.time()
        return CurriculumInfo(
            name=self.name,
            config=self.config,
            created_at=self.created_at,
            counters=CurriculumCounters(
                tasks_issued=self.tasks_issued,
                results_received=self.results_received,
                results_per_second=self.results_per_second(now),
                tasks_outstanding=len(self.outstanding),
                tasks_expired=self.tasks_expired,
                fits_completed=self.fits_completed,
                fits_pending=self.fits_pending,
                last_fit_at=self.last_fit_at,
                fits_stopped=self._fits.stopped,
            ),
        )

    def state(self, recent: int) -> CurriculumState:
        results = list(self.recent_results)[-recent:] if recent else []
        return CurriculumState(
            curriculum=self.info(),
            teacher=self.teacher.state(),
            fits=list(self.fit_events),
            recent_results=results,
        )

    def restore(self) -> None:
        """Rebuild the curriculum from its newest snapshot and the results stored after it (see the
        module docstring); before the service starts."""
        store, teacher = self._store, self.teacher
        stored = store.snapshot(self.id)
        after_seq = tasks_issued = issued_through = 0
        waiting: list[int] = []
        awaited_then: list[int] = []
        if stored is not None:
            kept_from = teacher.history_kept_from(stored.teacher)
            teacher.restore(stored.teacher, store.history(self.id, stored.history_rows, kept_from))
            after_seq, tasks_issued, issued_through = stored.last_seq, stored.tasks_issued, stored.issued_through
            waiting, self._history_stored = stored.fits_waiting, stored.history_rows
            teacher.release_history(self._history_stored)
            awaited_then = stored.outstanding
        later_tasks = store.tasks_from(self.id, issued_through)
        self.tasks_issued = tasks_issued + len(later_tasks)
        self.issued_through = later_tasks[-1].index + 1 if later_tasks else issued_through
        self.results_received = self._snapshot_at = teacher.results_seen
        recorded = {fit.index: fit for fit in store.fits_since(self.id, teacher.results_seen)}
        due = deque(teacher.refit_job(index) for index in waiting)
        drawn_before = _tasks_drawn_before(later_tasks)
        models_found: list[tuple[Any, ...]] = []
        answered: set[int] = set()

        def draw_to(count: int) -> None:
            if count > teacher.tasks_drawn:
                teacher.skip(count - teacher.tasks_drawn)

        def install_recorded(results_applied: int) -> None:
            while due and (fit := recorded.get(due[0].index)) and fit.results_seen <= results_applied:
                draw_to(fit.tasks_sampled)
                self._install_stored(due.popleft(), fit, models_found)

        total = store.result_count(self.id, after_seq)
        results = store.results(self.id, after_seq)
        for result in tqdm(
            results, total=total, desc=f"replaying {self.name}", unit="result", disable=None, leave=False
        ):
            install_recorded(teacher.results_seen)
            draw_to(drawn_before(teacher.results_seen))
            job = self._learn(result.task_index, result.task, result.reward, result.success, result.length)
            answered.add(result.task_index)
            if job is not None:
                due.append(job)
        install_recorded(teacher.results_seen)
        draw_to(self.issued_through)
        oldest_kept = self.issued_through - self._task_window
        recent_then = [index for index in awaited_then if index >= oldest_kept]
        for index, task, issued_at in store.awaited_tasks(self.id, recent_then, max(issued_through, oldest_kept)):
            if index not in answered:
                self.outstanding[index] = task
                self._awaiting.append((index, issued_at))
        self._expire(time.time())
        for job in due:  # never recorded: the process died first
            self._lost_fits.append(job)
            self._fits_waiting.add(job.index)
        self._restore_reports(models_found)
        if total or models_found:
            snapshot = self._snapshot()
            store.write_now([(INSERT_FIT, models_found), *snapshot_statements(self.id, snapshot)])
            self._snapshot_at, self._history_stored = snapshot.results_seen, teacher.history_size
            teacher.release_history(self._history_stored)

    def _install_stored(self, job: FitJob, fit: StoredFit, models_found: list[tuple[Any, ...]]) -> None:
        """Install a recorded fit from its stored model; one stored without a model (by a version-1
        service) runs again here, and its model is stored for next time."""
        if fit.error is not None:
            return
        try:
            if fit.model is not None:
                self.teacher.install(self.teacher.import_fit(json.loads(fit.model)))
                return
            outcome = _rerun(job, fit)
            error = outcome.error
            if error is None:
                self.teacher.install(outcome.output)
        except Exception as exception:
            log.exception("curriculum %r: installing stored fit %d failed", self.name, fit.index)
            error = f"install failed: {type(exception).__name__}: {exception}"
        model = None if error is not None else json.dumps(self.teacher.export_fit(outcome.output))
        models_found.append(
            (self.id, fit.index, fit.tasks_sampled, fit.results_seen, fit.started_at, fit.finished_at, error, model)
        )

    def _restore_reports(self, models_found: list[tuple[Any, ...]]) -> None:
        """What the API reports about the past, read from the store rather than replayed."""
        store = self._store
        errors = {row[1]: row[6] for row in models_found}
        for fit in store.recent_fits(self.id, FIT_HISTORY):
            error = errors.get(fit.index, fit.error)
            self.fit_events.append(_fit_event(fit.index, fit.started_at, fit.finished_at, True, error))
        self.fits_completed = store.fit_count(self.id)
        self.last_fit_at = self.fit_events[-1].finished_at if self.fit_events else None
        for result in store.recent_results(self.id, self.recent_results.maxlen or 0):
            self.recent_results.append(
                RecentResult(
                    task_id=self.task_id(result.task_index),
                    params=result.task,
                    reward=result.reward,
                    success=result.success,
                    length=result.length,
                    received_at=result.received_at,
                )
            )

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


def _rerun(job: FitJob, recorded: StoredFit) -> FitOutcome:
    """Run a job again, keeping the live run's timing so the fit history survives restarts.

    A fit that failed live fails again here without running: had it succeeded on replay, the
    rebuilt teacher would sample from a model the live one never had.
    """
    if recorded.error is not None:
        return FitOutcome(job.index, None, recorded.error, recorded.started_at, recorded.finished_at)
    outcome = run_fit(job)
    return FitOutcome(outcome.index, outcome.output, outcome.error, recorded.started_at, recorded.finished_at)


def _tasks_drawn_before(tasks: list[StoredTask]) -> Callable[[int], int]:
    """Maps a count of applied results to how many tasks the live teacher had drawn by then."""
    marks = iter(tasks)
    drawn = 0
    pending = next(marks, None)

    def drawn_before(results_applied: int) -> int:
        nonlocal drawn, pending
        while pending is not None and pending.results_seen <= results_applied:
            drawn = pending.index + 1
            pending = next(marks, None)
        return drawn

    return drawn_before


class CurriculumRegistry:
    """Every curriculum of one service, loaded from and written to one store."""

    def __init__(self, store: Store, metrics: ServiceMetrics, settings: Settings) -> None:
        self._store = store
        self._metrics = metrics
        self._settings = settings
        self._fits = FitRunner(settings.fit_processes, settings.fit_timeout_s, metrics)
        self._builds = ThreadPoolExecutor(max_workers=1, thread_name_prefix="teacher-builds")
        self._curricula: dict[str, Curriculum] = {}

    def restore(self) -> None:
        """Rebuild every stored curriculum; call before ``start``."""
        for stored in self._store.curricula():
            started = time.perf_counter()
            curriculum = self._build(stored)
            curriculum.restore()
            self._curricula[stored.name] = curriculum
            log.info(
                "restored curriculum %r in %.2f s: %d tasks, %d results, %d fits",
                stored.name,
                time.perf_counter() - started,
                curriculum.tasks_issued,
                curriculum.results_received,
                curriculum.fits_completed,
            )

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Start writing and fitting on ``loop``, the running loop."""
        self._store.start(loop)
        self._fits.start(loop)
        for curriculum in self._curricula.values():
            curriculum.resume()

    def close(self) -> None:
        self._fits.close()
        self._store.close()
        self._builds.shutdown(wait=False, cancel_futures=True)

    @property
    def fits_stopped(self) -> str | None:
        """Why no fits run any more, if the fit processes kept dying."""
        return self._fits.stopped

    def __len__(self) -> int:
        return len(self._curricula)

    def __iter__(self) -> Iterator[Curriculum]:
        return iter(list(self._curricula.values()))

    def get(self, name: str) -> Curriculum:
        try:
            return self._curricula[name]
        except KeyError:
            raise UnknownCurriculum(name) from None

    async def create(self, name: str, spec: TypedSpec) -> tuple[Curriculum, bool]:
        """Create a curriculum, or return the identical one that exists (``created`` False).

        Raises ``CurriculumConflict`` when the name holds a different one, ``ValueError`` when the
        teacher rejects its parameters."""
        existing = self._curricula.get(name)
        if existing is not None:
            if existing.spec != spec:
                raise CurriculumConflict(
                    f"curriculum {name!r} already exists with a different configuration "
                    f"(teacher {existing.spec.teacher!r}, seed {existing.spec.seed}); choose another name"
                )
            return existing, False
        curriculum_id = max((c.id for c in self._curricula.values()), default=0) + 1
        curriculum = self._build(StoredCurriculum(curriculum_id, name, spec.model_dump_json(), time.time()))
        # Registered before the write so a concurrent PUT sees it; the store's FIFO order puts this
        # row before any task written for it.
        self._curricula[name] = curriculum
        await self._store.write(
            [(INSERT_CURRICULUM, [(curriculum_id, name, spec.model_dump_json(), curriculum.created_at)])],
            on_abort=lambda: self._curricula.pop(name, None),
        )
        return curriculum, True

    def _build(self, stored: StoredCurriculum) -> Curriculum:
        return Curriculum(
            stored.id,
            stored.name,
            stored_spec(stored.spec),
            stored.created_at,
            self._store,
            self._fits,
            self._builds,
            self._metrics,
            self._settings,
        )
