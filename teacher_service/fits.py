"""Teacher model fits, off the request path.

A fit is seconds of scikit-learn EM, mostly Python that holds the GIL, so in a thread it would
stall the event loop that answers requests. Fits therefore run in one separate process, one at a
time in the order they fell due, at a lower CPU priority than the service; their outcomes come
back to the event loop in that same order. Jobs are pure, so when the process dies its unfinished
jobs go to a fresh one.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.process import BaseProcess
from multiprocessing.queues import Queue
from typing import Any

from threadpoolctl import threadpool_limits

from teacher_service.teachers import FitJob

log = logging.getLogger(__name__)

FIT_NICENESS = 5
"""Added to the fit process's nice value, so the scheduler favours the process serving requests."""

_LIVENESS_POLL_S = 0.5


@dataclass(frozen=True)
class FitOutcome:
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


def _fit_forever(jobs: Queue[FitJob | None], outcomes: Queue[FitOutcome]) -> None:
    """Fit until told to stop, or until the service is gone: a killed service sends no word, and
    the queues' pipes stay open because this process holds both of their ends.

    One BLAS thread: the mixtures are small, and a second thread spinning for work takes the core
    that the service needs to answer requests."""
    os.nice(FIT_NICENESS)
    threadpool_limits(limits=1)
    outcomes.cancel_join_thread()
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


class FitRunner:
    """Runs fit jobs in a background process and calls each job's ``on_done`` on the event loop,
    in submission order. Starts the process on the first job: most teachers never fit."""

    def __init__(self) -> None:
        self._context = multiprocessing.get_context("spawn")
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pending: deque[tuple[FitJob, OnFitDone]] = deque()
        self._process: BaseProcess | None = None
        self._jobs: Queue[FitJob | None] | None = None
        self._outcomes: Queue[FitOutcome] | None = None
        self._relay: threading.Thread | None = None
        self._closing = False

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop

    def submit(self, job: FitJob, on_done: OnFitDone) -> None:
        """Queue a job; call from the event loop."""
        self._pending.append((job, on_done))
        if self._process is None:
            self._spawn()
        else:
            assert self._jobs is not None
            self._jobs.put(job)

    def close(self) -> None:
        """Stop without waiting for a running fit: the store holds what a restart needs to redo it."""
        self._closing = True
        if self._process is None:
            return
        self._process.kill()
        self._process.join()
        assert self._relay is not None
        self._relay.join()
        self._retire()

    def _retire(self) -> None:
        """Let go of a stopped process's queues."""
        for channel in (self._jobs, self._outcomes):
            if channel is not None:
                channel.cancel_join_thread()
                channel.close()
        self._process = self._jobs = self._outcomes = None

    def _spawn(self) -> None:
        """Start a fit process and hand it every job not yet done, in order."""
        jobs: Queue[FitJob | None] = self._context.Queue()
        outcomes: Queue[FitOutcome] = self._context.Queue()
        process = self._context.Process(target=_fit_forever, args=(jobs, outcomes), name="teacher-fits", daemon=True)
        process.start()
        self._process, self._jobs, self._outcomes = process, jobs, outcomes
        for job, _ in self._pending:
            jobs.put(job)
        self._relay = threading.Thread(
            target=self._relay_outcomes, args=(process, outcomes), name="teacher-fit-relay", daemon=True
        )
        self._relay.start()

    def _relay_outcomes(self, process: BaseProcess, outcomes: Queue[FitOutcome]) -> None:
        """Pass outcomes to the event loop; report a dead process so the loop can replace it."""
        assert self._loop is not None
        while not self._closing:
            try:
                outcome = outcomes.get(timeout=_LIVENESS_POLL_S)
            except queue.Empty:
                if process.is_alive() or self._closing:
                    continue
                self._call_on_loop(self._replace, process)
                return
            self._call_on_loop(self._deliver, outcome)

    def _call_on_loop(self, callback: Callable[..., None], *args: Any) -> None:
        assert self._loop is not None
        try:
            self._loop.call_soon_threadsafe(callback, *args)
        except RuntimeError:
            log.info("event loop closed; fit results are dropped and a restart redoes them")

    def _deliver(self, outcome: FitOutcome) -> None:
        job, on_done = self._pending.popleft()
        assert job.index == outcome.index, f"fit {outcome.index} came back while fit {job.index} was due"
        on_done(outcome)

    def _replace(self, dead: BaseProcess) -> None:
        if self._closing or dead is not self._process:
            return
        log.error(
            "the fit process died (exit code %s); restarting it with %d pending fits", dead.exitcode, len(self._pending)
        )
        self._retire()
        self._spawn()
