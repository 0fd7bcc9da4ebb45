"""A process pool that Ctrl-C stops cleanly: for commands that play many episodes in
worker processes (``evaluate``, ``bakeoff``'s final evaluations, the benchmark scripts)."""

from __future__ import annotations

import signal
import threading
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


class StoppablePool(ProcessPoolExecutor):
    """A ``ProcessPoolExecutor`` whose workers leave Ctrl-C to the parent, and whose ``with`` block
    cancels the queued work on the way out: stopped (Ctrl-C) or failed, only the work already
    running plays out."""

    def submit(self, fn: Callable[..., Result], /, *args: Any, **kwargs: Any) -> Future[Result]:
        with _children_ignore_ctrl_c():  # the pool starts its processes as work is submitted
            return super().submit(fn, *args, **kwargs)

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, traceback: TracebackType | None
    ) -> None:
        self.shutdown(cancel_futures=True)
