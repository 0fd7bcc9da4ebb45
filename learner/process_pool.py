"""A process pool that Ctrl-C stops cleanly and a killed parent does not outlive: for commands that
play many episodes in worker processes (``evaluate``, ``bakeoff``'s final evaluations, the
benchmark scripts)."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import contextmanager
from types import TracebackType
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


def _start_worker(parent: int, initializer: Callable[..., object] | None, initargs: tuple[Any, ...]) -> None:
    threading.Thread(target=_leave_with_parent, args=(parent,), name="parent-watch", daemon=True).start()
    if initializer is not None:
        initializer(*initargs)


class StoppablePool(ProcessPoolExecutor):
    """A ``ProcessPoolExecutor`` whose workers leave Ctrl-C to the parent and exit when the parent
    dies however it dies, and whose ``with`` block cancels the queued work on the way out: stopped
    (Ctrl-C) or failed, only the work already running plays out."""

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

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, traceback: TracebackType | None
    ) -> None:
        self.shutdown(cancel_futures=True)
