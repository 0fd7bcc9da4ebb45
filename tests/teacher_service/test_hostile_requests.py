"""Requests a careful reviewer would send to a shared service: each is refused with a 4xx within a
second, and ``/healthz`` keeps answering within 100 ms while they run (a real uvicorn process)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import httpx
import pytest

from teacher_service.process import ServiceProcess

HEALTH_LATENCY_S = 0.1
ANSWER_WITHIN_S = 1.0


def _space_with(kuka_space: list[dict[str, Any]], name: str, **bounds: float) -> list[dict[str, Any]]:
    return [{**p, **bounds} if p["name"] == name else p for p in kuka_space]


def _hostile_requests(kuka_space: list[dict[str, Any]]) -> dict[str, Callable[[httpx.Client], httpx.Response]]:
    def put(teacher: str, space: list[dict[str, Any]], **params: Any) -> Callable[[httpx.Client], httpx.Response]:
        body = {"teacher": teacher, "space": space, "params": params}
        return lambda http: http.put("/curricula/hostile", json=body)

    wide = _space_with(kuka_space, "rnd_obj_x", high=1e6, hardest=1e6)
    far = _space_with(kuka_space, "rnd_obj_x", low=1e15, high=1e15 + 1, easiest=1e15, hardest=1e15 + 1)
    return {
        "a lesson plan of millions of lessons": put("manual", wide),
        "a lesson plan whose steps are lost to rounding": put("manual", far),
        "a billion interpolated lessons": put("manual", kuka_space, steps=10**9),
        "a 43 TiB nearest-neighbour buffer": put("alp-gmm", kuka_space, buffer_size=10**12),
        "a billion results between fits": put("alp-gmm", kuka_space, fit_rate=10**9),
        "a million EM restarts": put("alp-gmm", kuka_space, nb_em_init=10**6),
        "a million mixture components": put("alp-gmm", kuka_space, max_components=10**6),
        "a NaN parameter": lambda http: http.put(
            "/curricula/hostile",
            content=b'{"teacher": "manual", "space": [], "params": {"threshold": NaN}}',
            headers={"Content-Type": "application/json"},
        ),
        "a billion tasks at once": lambda http: http.post("/curricula/anything/tasks", json={"count": 10**9}),
        "a 10 MB body": lambda http: http.put("/curricula/hostile", content=b"x" * 10_000_000),
        "JSON nested 100,000 deep": lambda http: http.put(
            "/curricula/hostile", content=b"[" * 100_000, headers={"Content-Type": "application/json"}
        ),
        "a 60,000-character name": lambda http: http.put(f"/curricula/{'n' * 60_000}", json={}),
    }


@pytest.fixture()
def health_latencies(service: ServiceProcess) -> Iterator[list[float]]:
    """Polls ``/healthz`` every 20 ms in a thread while the test runs; yields the latencies."""
    latencies: list[float] = []
    stop = threading.Event()

    def poll() -> None:
        with httpx.Client(base_url=service.url, timeout=5.0) as client:
            while not stop.is_set():
                started = time.perf_counter()
                client.get("/healthz").raise_for_status()
                latencies.append(time.perf_counter() - started)
                stop.wait(0.02)

    poller = threading.Thread(target=poll, daemon=True)
    poller.start()
    yield latencies
    stop.set()
    poller.join()


def test_hostile_requests_are_refused_fast_and_the_service_stays_responsive(
    http: httpx.Client, kuka_space: list[dict[str, Any]], health_latencies: list[float]
) -> None:
    slow_or_accepted = {}
    for what, send in _hostile_requests(kuka_space).items():
        started = time.perf_counter()
        response = send(http)
        elapsed = time.perf_counter() - started
        if not (400 <= response.status_code < 500 and elapsed < ANSWER_WITHIN_S):
            slow_or_accepted[what] = (response.status_code, round(elapsed, 3), response.text[:200])
    # The battery can be over before a poller on a loaded machine had its turn: let it finish five.
    deadline = time.monotonic() + 5.0
    while len(health_latencies) < 5 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert not slow_or_accepted, slow_or_accepted
    assert http.get("/curricula/hostile").status_code == 404
    assert len(health_latencies) >= 5
    assert max(health_latencies) < HEALTH_LATENCY_S, sorted(health_latencies)[-5:]
