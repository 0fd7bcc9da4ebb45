"""Bodies of fit jobs for the fit runner's tests. They live in a module of their own because a fit
runs in a spawned process, which must import a job's function by name."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path


def sleep_then(seconds: float, value: object) -> object:
    """A fit that takes ``seconds`` and returns ``value``."""
    time.sleep(seconds)
    return value


def own_pid() -> int:
    return os.getpid()


def note_pid_then_sleep(path: str, seconds: float) -> None:
    """Write this process's id to ``path``, then hang for ``seconds``."""
    Path(path).write_text(str(os.getpid()))
    time.sleep(seconds)


def kill_own_process() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def exit_once(marker: str, value: object) -> object:
    """Exit with code 3 the first time (leaving ``marker``), return ``value`` after."""
    if not Path(marker).exists():
        Path(marker).touch()
        os._exit(3)
    return value


def thread_pools() -> list[dict[str, object]]:
    """The native thread pools loaded in this process (BLAS, OpenMP), with their thread counts."""
    from threadpoolctl import threadpool_info

    return threadpool_info()
