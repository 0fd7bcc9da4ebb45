"""Run a private teacher service as a child process for the length of one training run."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path

from teacher_service.process import ServiceProcess

STARTUP_TIMEOUT_S = 60.0
SHUTDOWN_TIMEOUT_S = 15.0
DATABASE_FILE = "teacher.sqlite"
LOG_FILE = "teacher.log"


def launch_local_teacher_service(run_dir: Path, stack: contextlib.ExitStack) -> Callable[[], str]:
    """Start ``kuka-curriculum serve`` on a free localhost port with its database in ``run_dir``, and
    return a wait for its URL; the service stops when ``stack`` closes.

    Not waiting here lets the caller start Ray while the service starts: the two start-ups overlap
    (about 2 s of every command on 2 cores). The child gets its own session, so a Ctrl-C meant for
    training does not take the teacher down before the workers have delivered their last results.
    Raises ``RuntimeError`` from the wait if the service exits or does not answer in time.
    """
    run_dir = Path(run_dir)
    service = ServiceProcess(run_dir / DATABASE_FILE, log_path=run_dir / LOG_FILE, own_session=True).launch()
    stack.callback(service.stop, SHUTDOWN_TIMEOUT_S)

    def ready() -> str:
        service.wait_until_healthy(STARTUP_TIMEOUT_S)
        return service.url

    return ready


@contextlib.contextmanager
def local_teacher_service(run_dir: Path) -> Iterator[str]:
    """The service of ``launch_local_teacher_service``, ready, for the length of the block; yields its URL."""
    with contextlib.ExitStack() as stack:
        yield launch_local_teacher_service(run_dir, stack)()
