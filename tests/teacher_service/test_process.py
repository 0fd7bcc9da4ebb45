"""``ServiceProcess``: a port it chose that another process binds first is left for another one at the first
start (two test processes, or Ray, can be handed the same free port by the OS), while a port the caller named,
or the port of a service that has answered once, stays what it is."""

from __future__ import annotations

import json
import os
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import httpx
import pytest

from teacher_service.process import ServiceProcess


@contextmanager
def listener_on(port: int) -> Iterator[None]:
    """Another process's server on ``port`` for the length of the block."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", port))
        taken.listen()
        yield


@contextmanager
def another_service_on(port: int) -> Iterator[None]:
    """Another teacher service on ``port``: it answers ``/healthz`` with 200, as every one does, and its own
    process id."""

    class Healthy(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            body = json.dumps({"status": "ok", "curricula": 0, "pid": os.getpid()}).encode()
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", port), Healthy)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield
    finally:
        server.shutdown()
        server.server_close()


def test_another_services_answer_on_the_chosen_port_is_not_taken_for_its_own(tmp_path: Path) -> None:
    """The child fails to bind a second or so after it starts; meanwhile the port's owner answers 200. The
    start must wait for its own child's answer, and so move on, not return at once with a dead child."""
    service = ServiceProcess(tmp_path / "teacher.db")
    chosen = service.port
    with another_service_on(chosen), service:
        assert service.port != chosen
        assert httpx.get(f"{service.url}/healthz", timeout=5).json()["pid"] == service.pid


def test_a_chosen_port_taken_before_the_first_start_moves_to_another(tmp_path: Path) -> None:
    service = ServiceProcess(tmp_path / "teacher.db")
    chosen = service.port
    with listener_on(chosen), service:
        assert service.port != chosen
        assert httpx.get(f"{service.url}/healthz", timeout=5).json()["status"] == "ok"
        # Answered once, the service keeps its port: a restart serves at the same URL.
        answered = service.port
        service.kill()
        service.start()
        assert service.port == answered


def test_a_port_the_caller_named_is_not_moved(tmp_path: Path) -> None:
    named = ServiceProcess(tmp_path / "teacher.db").port
    service = ServiceProcess(tmp_path / "teacher.db", port=named)
    with listener_on(named), pytest.raises(RuntimeError, match="address already in use"):
        service.start(30)
    assert service.port == named
