"""Run the teacher service as a child process on this machine.

For a training run that starts its own teacher, and for tests that need a real server they can
kill. The child runs ``kuka-curriculum serve`` with the same interpreter.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType

import httpx

PORT_TAKEN = "address already in use"
"""uvicorn's words when the port it was given is bound by another process."""
PORT_MOVES = 3
"""Other ports a first start tries when the one chosen was taken before the child could bind it."""


def free_port(host: str = "127.0.0.1") -> int:
    """A port that was free a moment ago (the OS picks it)."""
    with socket.socket() as probe:
        probe.bind((host, 0))
        port: int = probe.getsockname()[1]
        return port


class ServiceProcess:
    """``kuka-curriculum serve`` on ``db``; ``start`` waits until ``/healthz`` answers.

    The port is chosen once, so a restart (``kill`` then ``start``) serves at the same URL. A port this
    class chose can be taken by another process before the child binds it (the OS hands the same free
    ports to everyone on the machine); the first start then moves to another one (``url`` says which).
    The child's output goes to ``log_path`` (next to the database by default). With
    ``own_session`` the child leaves the caller's session, so a Ctrl-C meant for the caller does
    not stop the service before the caller has delivered its last results.
    """

    def __init__(
        self,
        db: Path,
        *,
        host: str = "127.0.0.1",
        port: int | None = None,
        env: Mapping[str, str] | None = None,
        log_path: Path | None = None,
        own_session: bool = False,
    ) -> None:
        self.db = Path(db)
        self.host = host
        self.port = port or free_port(host)
        self._may_move_port = port is None
        """True until the service first answers at its port, if this class chose it."""
        self.env = {**os.environ, **(env or {})}
        self.log_path = log_path or self.db.with_suffix(".log")
        self.own_session = own_session
        self._process: subprocess.Popen[bytes] | None = None
        self._log_start = 0
        """Where the log stood when the child last launched."""

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    @property
    def pid(self) -> int:
        if self._process is None:
            raise RuntimeError("the service is not running")
        return self._process.pid

    def start(self, timeout: float = 60.0) -> ServiceProcess:
        self.launch()
        self.wait_until_healthy(timeout)
        return self

    def launch(self) -> ServiceProcess:
        """Start the child without waiting for it, so a caller can start other things meanwhile;
        ``wait_until_healthy`` then waits for it."""
        if self._process is not None and self._process.poll() is None:
            raise RuntimeError(f"the service at {self.url} is already running")
        self.db.parent.mkdir(parents=True, exist_ok=True)
        self._log_start = self.log_path.stat().st_size if self.log_path.exists() else 0
        command = [
            sys.executable,
            "-m",
            "kuka_curriculum",
            "serve",
            "--host",
            self.host,
            "--port",
            str(self.port),
            "--db",
            str(self.db),
            "--log-level",
            "warning",
        ]
        with self.log_path.open("ab") as log:
            self._process = subprocess.Popen(
                command, stdout=log, stderr=subprocess.STDOUT, env=self.env, start_new_session=self.own_session
            )
        return self

    def wait_until_healthy(self, timeout: float) -> None:
        """Return once ``/healthz`` answers; raise ``RuntimeError`` (with the log's tail) if the child
        exits first or does not answer within ``timeout`` seconds (it is then killed)."""
        if self._process is None:
            raise RuntimeError("the service was not launched")
        deadline = time.monotonic() + timeout
        moves = PORT_MOVES
        while time.monotonic() < deadline:
            if self._process.poll() is not None:
                if self._may_move_port and moves > 0 and PORT_TAKEN in self._launch_log():
                    moves -= 1
                    self.port = free_port(self.host)
                    self.launch()
                    continue
                raise RuntimeError(
                    f"the teacher service at {self.url} exited with code {self._process.returncode}:\n"
                    f"{self._log_tail()}"
                )
            if self._answers():
                self._may_move_port = False
                return
            time.sleep(0.05)
        self.kill()
        raise RuntimeError(
            f"the teacher service did not answer {self.url}/healthz within {timeout:.0f} s:\n{self._log_tail()}"
        )

    def _answers(self) -> bool:
        """Whether this class's child answers ``/healthz``: another service that took the port first
        answers too, with its own process id, while the child is still on its way to failing to bind."""
        try:
            response = httpx.get(f"{self.url}/healthz", timeout=1.0)
            if response.status_code != 200:
                return False
            body = response.json()
        except (httpx.TransportError, ValueError):
            return False
        return isinstance(body, dict) and body.get("pid") == self.pid

    def _launch_log(self) -> str:
        """What the child wrote to the log since its last launch."""
        with self.log_path.open("rb") as log:
            log.seek(self._log_start)
            return log.read().decode(errors="replace")

    def _log_tail(self, lines: int = 30) -> str:
        return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])

    def stop(self, timeout: float = 30.0) -> None:
        """Shut down gracefully (SIGTERM), killing the process if it does not exit in time."""
        if self._process is None:
            return
        self._process.send_signal(signal.SIGTERM)
        try:
            self._process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()
        self._process = None

    def kill(self) -> None:
        """Die at once (SIGKILL), as in a crash: nothing is flushed or shut down."""
        if self._process is None:
            return
        self._process.kill()
        self._process.wait()
        self._process = None

    def __enter__(self) -> ServiceProcess:
        return self.start()

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, traceback: TracebackType | None
    ) -> None:
        self.stop()
