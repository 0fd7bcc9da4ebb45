"""A process pool that Ctrl-C stops cleanly and a killed parent does not outlive: for commands that
play many episodes in worker processes (``evaluate``, ``bakeoff``'s final evaluations, the
benchmark scripts)."""

from __future__ import annotations

import os
import queue
import signal
import threading
import time
from collections.abc import Callable, Collection, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import contextmanager
from types import FrameType, TracebackType
from typing import Any, TypeVar

Result = TypeVar("Result")


@contextmanager
def _children_ignore_ctrl_c() -> Iterator[None]:
    """Processes started inside this block ignore SIGINT from birth (Python keeps an inherited ignore).

    Ctrl-C reaches the whole process group. The parent decides what it means and stops the pool; a
    worker that died of it, even while still importing, would break the pool under the parent. The
    price: a Ctrl-C in the milliseconds it takes to start the processes goes unheard.
    """
    if threading.current_thread() is not threading.main_thread():
        yield  # only the main thread may set handlers, and only it receives Ctrl-C
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


PARENT_CHECK_S = 1.0
"""How often a worker looks for its parent: how long it outlives a parent killed with SIGKILL."""


def _leave_with_parent(parent: int) -> None:
    """Exit as soon as the parent is gone. A worker of a parent killed with SIGKILL would otherwise
    wait on its work queue for ever: it holds that queue's write end itself, so no end-of-file comes."""
    while os.getppid() == parent:
        time.sleep(PARENT_CHECK_S)
    os._exit(1)


CTRL_C_POLL_S = 0.1
"""How often a caller waiting on the pool looks for a held Ctrl-C: the longest it goes unanswered."""


def _start_worker(parent: int, initializer: Callable[..., object] | None, initargs: tuple[Any, ...]) -> None:
    threading.Thread(target=_leave_with_parent, args=(parent,), name="parent-watch", daemon=True).start()
    if initializer is not None:
        initializer(*initargs)


class StoppablePool(ProcessPoolExecutor):
    """A ``ProcessPoolExecutor`` whose workers leave Ctrl-C to the parent and exit when the parent
    dies however it dies, and whose ``with`` block cancels the queued work on the way out: stopped
    (Ctrl-C) or failed, only the work already running plays out.

    Inside the ``with`` block the parent holds a Ctrl-C until a safe point (``as_completed``,
    ``result``, or the block's end) and then hands it to the handler it replaced. A
    ``KeyboardInterrupt`` raised wherever the main thread happens to be can land inside the
    executor's own code, between a lock's acquire and the ``with`` that would release it; the
    executor's manager thread then waits on that lock for ever, and so does the shutdown.
    """

    def __init__(
        self,
        max_workers: int | None = None,
        *,
        initializer: Callable[..., object] | None = None,
        initargs: tuple[Any, ...] = (),
        **options: Any,
    ) -> None:
        super().__init__(
            max_workers, initializer=_start_worker, initargs=(os.getpid(), initializer, initargs), **options
        )
        self._ctrl_c_held = False
        self._replaced_handler: Callable[[int, FrameType | None], Any] | None = None

    def submit(self, fn: Callable[..., Result], /, *args: Any, **kwargs: Any) -> Future[Result]:
        # Every process starts at the first submit, in one window that ignores Ctrl-C: a Ctrl-C that
        # lands while it is ignored is lost. Left to itself the pool starts a process only when none is
        # idle, so it kept starting them (each submit ignoring Ctrl-C) well into a run of submits, and
        # the Ctrl-C tests lost their Ctrl-C there; ignoring it around every submit lost them too.
        if getattr(self, "_executor_manager_thread", True) is None:
            with _children_ignore_ctrl_c():
                self._launch_processes()  # type: ignore[attr-defined]
                return super().submit(fn, *args, **kwargs)
        return super().submit(fn, *args, **kwargs)

    def as_completed(self, futures: Collection[Future[Result]]) -> Iterator[Future[Result]]:
        """``futures`` as they finish, like ``concurrent.futures.as_completed``; a Ctrl-C held while
        they run is handed on within ``CTRL_C_POLL_S``."""
        finished: queue.SimpleQueue[Future[Result]] = queue.SimpleQueue()
        for future in futures:
            future.add_done_callback(finished.put)
        remaining = len(futures)
        while remaining:
            self._hand_on_ctrl_c()
            try:
                future = finished.get(timeout=CTRL_C_POLL_S)
            except queue.Empty:
                continue
            remaining -= 1
            yield future

    def result(self, future: Future[Result]) -> Result:
        """``future.result()``, handing on a Ctrl-C held while it waits."""
        (done,) = tuple(self.as_completed((future,)))
        return done.result()

    def _hold_ctrl_c(self, signum: int, frame: FrameType | None) -> None:
        self._ctrl_c_held = True

    def _hand_on_ctrl_c(self) -> None:
        if self._ctrl_c_held and self._replaced_handler is not None:
            self._ctrl_c_held = False
            self._replaced_handler(signal.SIGINT, None)

    def __enter__(self) -> StoppablePool:
        handler = signal.getsignal(signal.SIGINT)
        # Only the main thread may set handlers; SIG_IGN and SIG_DFL have nothing to hand a Ctrl-C to.
        if threading.current_thread() is threading.main_thread() and callable(handler):
            self._replaced_handler = handler
            signal.signal(signal.SIGINT, self._hold_ctrl_c)
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, traceback: TracebackType | None
    ) -> None:
        try:
            self.shutdown(cancel_futures=True)
        finally:
            if self._replaced_handler is not None:
                signal.signal(signal.SIGINT, self._replaced_handler)
        if exc_type is None:
            self._hand_on_ctrl_c()
