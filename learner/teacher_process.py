"""Run a private teacher service as a child process for the length of one training run."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

from teacher_service.process import ServiceProcess

STARTUP_TIMEOUT_S = 60.0
SHUTDOWN_TIMEOUT_S = 15.0
DATABASE_FILE = "teacher.sqlite"
LOG_FILE = "teacher.log"


@contextlib.contextmanager
def local_teacher_service(run_dir: Path) -> Iterator[str]:
    """Start ``kuka-curriculum serve`` on a free localhost port with its database in ``run_dir``; yield its URL.

    The child gets its own session, so a Ctrl-C meant for training does not take the teacher down
    before the workers have delivered their last results; it is stopped when the block exits.
    """
    run_dir = Path(run_dir)
    service = ServiceProcess(run_dir / DATABASE_FILE, log_path=run_dir / LOG_FILE, own_session=True)
    service.start(STARTUP_TIMEOUT_S)
    try:
        yield service.url
    finally:
        service.stop(SHUTDOWN_TIMEOUT_S)
