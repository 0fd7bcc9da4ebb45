"""Teacher model fits, off the request path, in fair turns between curricula.

A fit is seconds of scikit-learn EM, mostly Python that holds the GIL, so in a thread it would
stall the event loop that answers requests. Fits therefore run in a small pool of separate
processes at a lower CPU priority than the service. A process starts when a fit finds no idle one
(starting takes a second or more, longer on a busy machine) and then stays, so a service whose
curricula never fit starts none; one that dies or is killed is replaced at once. Every
curriculum has a lane in which

- at most one fit runs at a time and at most one waits: a fit that falls due while the previous
  one still waits replaces it, and the replaced one completes as superseded;
- its outcomes come back to the event loop in the order its fits fell due.

When a process is free, the lane that has been waiting longest starts its fit (round robin), so
as long as the pool has a process for each busy curriculum, one curriculum's long fits delay no
other's. A fit that runs past the time limit is abandoned: its process is killed, the next fit
gets a fresh one, and the outcome says why, so the teacher keeps its previous model.

Jobs are pure, so a fit whose process died runs again in a fresh one. Processes that die
``MAX_DEATHS_IN_A_ROW`` times with no fit finishing in between point at something a fresh
process will not cure (memory, a crashing library): the runner then stops, every waiting or
running fit completes with the reason, later fits complete with it at once, and ``stopped`` says
why. It stays stopped until the service restarts; teachers keep sampling from their last models.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
import queue
import signal
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.context import SpawnContext
from multiprocessing.queues import Queue
from typing import Any

from threadpoolctl import threadpool_limits

from teacher_service.metrics import ServiceMetrics
from teacher_service.teachers import FitJob

log = logging.getLogger(__name__)

FIT_NICENESS = 5
"""Added to each fit process's nice value, so the scheduler favours the process serving requests."""

MAX_DEATHS_IN_A_ROW = 3
"""Fit processes that may die with no fit finishing in between before the runner stops."""

_LIVENESS_POLL_S = 0.5


@dataclass(frozen=True)
class FitOutcome:
    """What became of one fit: ``error is None`` means install ``output``; otherwise the fit is
    recorded with its error and nothing is installed."""

    index: int
    output: Any
    error: str | None
    started_at: float
    finished_at: float


def run_fit(job: FitJob) -> FitOutcome:
    """Run a job, turning a failure into an outcome so the caller decides what it means."""
    started = time.time()
    try:
        output, error = job.run(), None
    except Exception as exception:
        log.exception("fit %d failed", job.index)
        output, error = None, f"{type(exception).__name__}: {exception}"
    return FitOutcome(job.index, output, error, started, time.time())


def _fit_forever(jobs: Queue[FitJob | None], outcomes: Queue[FitOutcome | None]) -> None:
    """Say ready once imported, then fit until told to stop, or until the service is gone: a
    killed service sends no word, and the queues' pipes stay open because this process holds both
    of their ends.

    One BLAS and one OpenMP thread: the mixtures are small, and a second thread spinning for work
    takes the core that the service or another curriculum's fit needs. The limits apply to the
    libraries loaded when they are set, so the fit libraries are imported first (scikit-learn
    brings its own OpenMP runtime, which would otherwise run k-means on every core)."""
    os.nice(FIT_NICENESS)
    # Imported before saying ready, so that no fit's time limit pays for it; the service itself
    # imports it only if it ever fits in place (a version-1 database).
    import sklearn.mixture  # noqa: F401

    threadpool_limits(limits=1)
    outcomes.cancel_join_thread()
    outcomes.put(None)
    service = multiprocessing.parent_process()
    while service is None or service.is_alive():
        try:
            job = jobs.get(timeout=_LIVENESS_POLL_S)
        except queue.Empty:
            continue
        if job is None:
            return
        outcomes.put(run_fit(job))


OnFitDone = Callable[[FitOutcome], None]


@dataclass(eq=False)
class _Fit:
    curriculum: str
    job: FitJob
    outcome: FitOutcome | None = None


@dataclass(eq=False)
class _Lane:
    """One curriculum's fits: those not yet delivered in due order, the one waiting for a process
    and the one running."""

    on_done: OnFitDone
    undelivered: deque[_Fit] = field(default_factory=deque)
    waiting: _Fit | None = None
    running: _Fit | None = None


class _Worker:
    """One fit process, its two queues, and the thread that relays what it sends to the loop."""

    def __init__(self, context: SpawnContext) -> None:
        self.jobs: Queue[FitJob | None] = context.Queue()
        self.outcomes: Queue[FitOutcome | None] = context.Queue()
        self.process = context.Process(
            target=_fit_forever, args=(self.jobs, self.outcomes), name="teacher-fits", daemon=True
        )
        self.relay: threading.Thread | None = None
        self.ready = False
        self.fit: _Fit | None = None
        self.started_at = 0.0
        self.deadline: asyncio.TimerHandle | None = None

    def release(self) -> None:
        """Let go of a stopped process's queues and thread."""
        if self.deadline is not None:
            self.deadline.cancel()
        if self.relay is not None and self.relay is not threading.current_thread():
            self.relay.join()
        for channel in (self.jobs, self.outcomes):
            channel.cancel_join_thread()
            channel.close()


def _describe_exit(exitcode: int | None) -> str:
    """A process's end in words: its exit code, or the signal that killed it."""
    if exitcode is not None and exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exit code {exitcode}"


class FitRunner:
    """Runs fit jobs in up to ``processes`` background processes, in turns between curricula (see
    the module docstring), and calls each job's ``on_done`` on the event loop."""

    def __init__(self, processes: int, timeout_s: float, metrics: ServiceMetrics) -> None:
        if processes < 1:
            raise ValueError(f"a fit runner needs at least one process, got {processes}")
        self._context = multiprocessing.get_context("spawn")
        self._size = processes
        self._timeout_s = timeout_s
        self._metrics = metrics
        self._loop: asyncio.AbstractEventLoop | None = None
        self._lanes: dict[str, _Lane] = {}
        self._turns: deque[str] = deque()
        """Curricula with a waiting fit and none running, the longest waiting first."""
        self._workers: list[_Worker] = []
        """The pool: processes starting, idle or fitting."""
        self._leaving: list[_Worker] = []
        """Processes killed by the runner whose relay has not yet seen them go."""
        self._deaths_in_a_row = 0
        self._closing = False
        self.stopped: str | None = None
        """Why no fit runs any more, once processes kept dying; ``None`` while fits run."""

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop

    def submit(self, curriculum: str, job: FitJob, on_done: OnFitDone) -> None:
        """Queue a curriculum's fit; call from the event loop. ``on_done`` gets every outcome of
        the curriculum in submission order."""
        lane = self._lanes.get(curriculum)
        if lane is None:
            lane = self._lanes[curriculum] = _Lane(on_done)
            self._metrics.fit_timeouts.labels(curriculum)
            self._metrics.fits_superseded.labels(curriculum)
        fit = _Fit(curriculum, job)
        lane.undelivered.append(fit)
        if self.stopped is not None:
            self._fail(fit, f"fits stopped: {self.stopped}")
            return
        if lane.waiting is not None:
            self._supersede(lane.waiting, fit)
        self._wait(lane, fit)
        self._dispatch()

    def close(self) -> None:
        """Stop without waiting for running fits: the store holds what a restart needs to redo them."""
        self._closing = True
        workers, self._workers = self._workers + self._leaving, []
        self._leaving = []
        for worker in workers:
            worker.process.kill()
        for worker in workers:
            worker.process.join()
            worker.release()

    def _wait(self, lane: _Lane, fit: _Fit) -> None:
        lane.waiting = fit
        if lane.running is None and fit.curriculum not in self._turns:
            self._turns.append(fit.curriculum)

    def _supersede(self, older: _Fit, newer: _Fit) -> None:
        self._metrics.fits_superseded.labels(older.curriculum).inc()
        self._fail(older, f"superseded by fit {newer.job.index}")

    def _fail(self, fit: _Fit, error: str, started_at: float | None = None) -> None:
        now = time.time()
        self._finish(fit, FitOutcome(fit.job.index, None, error, now if started_at is None else started_at, now))

    def _finish(self, fit: _Fit, outcome: FitOutcome) -> None:
        """Record an outcome and deliver every outcome of the lane that no earlier fit holds up."""
        fit.outcome = outcome
        lane = self._lanes[fit.curriculum]
        while lane.undelivered and (ready := lane.undelivered[0].outcome) is not None:
            lane.undelivered.popleft()
            lane.on_done(ready)

    def _dispatch(self) -> None:
        """Give idle processes to waiting lanes in turn; start processes for lanes still waiting."""
        if self._closing or self.stopped is not None:
            return
        idle = [worker for worker in self._workers if worker.ready and worker.fit is None]
        while self._turns and idle:
            lane = self._lanes[self._turns.popleft()]
            fit, lane.waiting = lane.waiting, None
            assert fit is not None
            lane.running = fit
            self._run(idle.pop(), fit)
        starting = sum(not worker.ready for worker in self._workers)
        while len(self._workers) < self._size and starting < len(self._turns):
            self._spawn()
            starting += 1

    def _run(self, worker: _Worker, fit: _Fit) -> None:
        assert self._loop is not None
        worker.fit = fit
        worker.started_at = time.time()
        worker.jobs.put(fit.job)
        worker.deadline = self._loop.call_later(self._timeout_s, self._abandon, worker)

    def _spawn(self) -> None:
        worker = _Worker(self._context)
        worker.process.start()
        worker.relay = threading.Thread(target=self._relay, args=(worker,), name="teacher-fit-relay", daemon=True)
        worker.relay.start()
        self._workers.append(worker)

    def _relay(self, worker: _Worker) -> None:
        """Pass a process's messages to the event loop, then word that it is gone."""
        while not self._closing:
            try:
                message = worker.outcomes.get(timeout=_LIVENESS_POLL_S)
            except queue.Empty:
                if worker.process.is_alive():
                    continue
                worker.process.join()
                self._call_on_loop(self._gone, worker)
                return
            self._call_on_loop(self._received, worker, message)

    def _call_on_loop(self, callback: Callable[..., None], *args: Any) -> None:
        assert self._loop is not None
        try:
            self._loop.call_soon_threadsafe(callback, *args)
        except RuntimeError:
            log.info("event loop closed; fit results are dropped and a restart redoes them")

    def _received(self, worker: _Worker, message: FitOutcome | None) -> None:
        if self._closing or worker not in self._workers:
            return
        if message is None:
            worker.ready = True
            self._dispatch()
            return
        fit = worker.fit
        assert fit is not None and fit.job.index == message.index, f"fit {message.index} came back unasked"
        assert worker.deadline is not None
        worker.deadline.cancel()
        worker.fit = None
        self._deaths_in_a_row = 0
        self._vacate(fit)
        self._dispatch()
        self._finish(fit, message)

    def _vacate(self, fit: _Fit) -> None:
        """The lane's running fit is over; its waiting one, if any, takes its turn."""
        lane = self._lanes[fit.curriculum]
        lane.running = None
        if lane.waiting is not None:
            self._turns.append(fit.curriculum)

    def _abandon(self, worker: _Worker) -> None:
        """Kill a process whose fit ran past the time limit; a fresh one takes its place."""
        fit = worker.fit
        if self._closing or fit is None or worker not in self._workers:
            return
        log.warning(
            "curriculum %r: fit %d ran past %g s; killing its process", fit.curriculum, fit.job.index, self._timeout_s
        )
        self._workers.remove(worker)
        self._leaving.append(worker)
        worker.process.kill()
        worker.fit = None
        self._metrics.fit_timeouts.labels(fit.curriculum).inc()
        self._vacate(fit)
        self._spawn()
        self._dispatch()
        self._fail(fit, f"abandoned after {self._timeout_s:g} s", started_at=worker.started_at)

    def _gone(self, worker: _Worker) -> None:
        """A process has ended: one the runner killed is let go; any other died, and its fit runs
        again in a fresh process unless processes keep dying."""
        if self._closing:
            return
        if worker in self._leaving:
            self._leaving.remove(worker)
            worker.release()
            return
        self._workers.remove(worker)
        worker.release()
        how = _describe_exit(worker.process.exitcode)
        self._deaths_in_a_row += 1
        self._metrics.fit_process_deaths.inc()
        fit, worker.fit = worker.fit, None
        log.error(
            "a fit process died (%s) %s; %d death(s) in a row",
            how,
            f"running fit {fit.job.index} of {fit.curriculum!r}" if fit else "while idle",
            self._deaths_in_a_row,
        )
        if fit is not None:
            lane = self._lanes[fit.curriculum]
            lane.running = None
            if lane.waiting is not None:
                self._supersede(fit, lane.waiting)
            else:
                self._wait(lane, fit)
        if self._deaths_in_a_row >= MAX_DEATHS_IN_A_ROW:
            self._stop(
                f"fit processes died {self._deaths_in_a_row} times in a row without finishing a fit "
                f"(the last: {how}); fits resume when the service restarts"
            )
            return
        self._spawn()
        self._dispatch()

    def _stop(self, reason: str) -> None:
        """Run no more fits: kill the pool and complete every waiting and running fit with ``reason``."""
        log.error("fits stopped: %s", reason)
        self.stopped = reason
        self._metrics.fits_stopped.set(1)
        unfinished = []
        for worker in self._workers:
            worker.process.kill()
            if worker.fit is not None:
                unfinished.append(worker.fit)
        self._leaving += self._workers
        self._workers = []
        self._turns.clear()
        for lane in self._lanes.values():
            unfinished += [fit for fit in (lane.waiting, lane.running) if fit is not None and fit not in unfinished]
            lane.waiting = lane.running = None
        for fit in unfinished:
            self._fail(fit, f"fits stopped: {reason}")
