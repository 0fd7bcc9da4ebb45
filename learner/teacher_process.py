"""Run a private teacher service as a child process for the length of one training run."""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx

STARTUP_TIMEOUT_S = 60.0
SHUTDOWN_TIMEOUT_S = 15.0
DATABASE_FILE = "teacher.sqlite"
LOG_FILE = "teacher.log"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@contextlib.contextmanager
def local_teacher_service(run_dir: Path) -> Iterator[str]:
    """Start ``kuka-curriculum serve`` on a free localhost port with its database in ``run_dir``; yield its URL.

    The child gets its own session, so a Ctrl-C meant for training does not take the teacher down
    before the workers have delivered their last results; it is stopped when the block exits.
    """
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    command = [sys.executable, "-m", "common.cli", "serve", "--port", str(port),
               "--db", str(run_dir / DATABASE_FILE), "--log-level", "warning"]
    with (run_dir / LOG_FILE).open("ab") as log:
        process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        _wait_until_healthy(process, url, run_dir / LOG_FILE)
        yield url
    finally:
        process.terminate()
        try:
            process.wait(SHUTDOWN_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _wait_until_healthy(process: subprocess.Popen, url: str, log_path: Path) -> None:
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while time.monotonic() < deadline:
        if process.poll() is not None:
            tail = log_path.read_text(errors="replace")[-2000:]
            raise RuntimeError(f"the teacher service exited with code {process.returncode} while starting:\n{tail}")
        with contextlib.suppress(httpx.HTTPError):
            if httpx.get(f"{url}/healthz", timeout=1.0).status_code == 200:
                return
        time.sleep(0.2)
    raise RuntimeError(
        f"the teacher service did not answer at {url} within {STARTUP_TIMEOUT_S:.0f} s (log: {log_path})"
    )
