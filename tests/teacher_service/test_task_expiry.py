"""Tasks handed out and never reported expire, so a curriculum's memory of them stays bounded; a late
result for an expired task is counted and ignored (a real uvicorn and SQLite file, and a SIGKILL; a
full disk through the in-process service)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from in_process_service import InProcessService

from teacher_service.process import ServiceProcess

WINDOW = 5
TTL_S = 1.5


@pytest.fixture()
def db(tmp_path: Path) -> Path:
    return tmp_path / "teacher.db"


def _service(db: Path, ttl_s: float = TTL_S, snapshot_every: int = 1000) -> ServiceProcess:
    env = {"KC_TASK_WINDOW": str(WINDOW), "KC_TASK_TTL_S": str(ttl_s), "KC_SNAPSHOT_EVERY": str(snapshot_every)}
    return ServiceProcess(db, env=env)


@pytest.fixture()
def api(db: Path) -> Iterator[httpx.Client]:
    with _service(db) as service, httpx.Client(base_url=f"{service.url}/api/v1", timeout=10.0) as client:
        client.service = service  # type: ignore[attr-defined]
        yield client


def _create(api: httpx.Client, kuka_space: list[dict[str, Any]], name: str) -> None:
    assert api.put(f"/curricula/{name}", json={"teacher": "random", "space": kuka_space}).status_code == 201


def _draw(api: httpx.Client, name: str, count: int) -> list[str]:
    return [task["task_id"] for task in api.post(f"/curricula/{name}/tasks", json={"count": count}).json()["tasks"]]


def _report(api: httpx.Client, name: str, task_ids: list[str]) -> dict[str, int]:
    results = [{"task_id": task_id, "reward": 1.0} for task_id in task_ids]
    response = api.post(f"/curricula/{name}/results", json={"results": results})
    assert response.status_code == 200, response.text
    ack: dict[str, int] = response.json()
    return ack


def _counters(api: httpx.Client, name: str) -> dict[str, Any]:
    counters: dict[str, Any] = api.get(f"/curricula/{name}").json()["counters"]
    return counters


def test_a_task_expires_once_the_window_of_later_tasks_has_passed(api, kuka_space):
    _create(api, kuka_space, "window")
    ids = _draw(api, "window", WINDOW + 3)
    counters = _counters(api, "window")
    assert (counters["tasks_outstanding"], counters["tasks_expired"]) == (WINDOW, 3)

    assert _report(api, "window", ids[:2] + ids[-1:]) == {"accepted": 1, "duplicates": 0, "expired": 2}
    assert _report(api, "window", ids[-1:]) == {"accepted": 0, "duplicates": 1, "expired": 0}
    counters = _counters(api, "window")
    assert (counters["results_received"], counters["tasks_outstanding"]) == (1, WINDOW - 1)
    metrics = httpx.get(f"{api.service.url}/metrics").text
    assert 'kc_results_total{curriculum="window",outcome="expired"} 2.0' in metrics
    assert 'kc_tasks_expired_total{curriculum="window"} 3.0' in metrics


def test_a_task_expires_after_its_time_to_live(api, kuka_space):
    _create(api, kuka_space, "ttl")
    old = _draw(api, "ttl", 2)
    time.sleep(TTL_S + 0.2)
    new = _draw(api, "ttl", 1)
    assert _counters(api, "ttl")["tasks_outstanding"] == 1
    assert _report(api, "ttl", old + new) == {"accepted": 1, "duplicates": 0, "expired": 2}


@pytest.mark.parametrize("snapshot_every", [1, 1000], ids=["from-a-snapshot", "from-the-tasks"])
def test_a_restart_keeps_only_the_tasks_still_awaited(db, kuka_space, snapshot_every):
    with (
        _service(db, ttl_s=600, snapshot_every=snapshot_every) as service,
        httpx.Client(base_url=f"{service.url}/api/v1", timeout=10.0) as api,
    ):
        _create(api, kuka_space, "restart")
        ids = _draw(api, "restart", WINDOW + 2)
        _report(api, "restart", ids[-1:])
        service.kill()
    with (
        _service(db, ttl_s=600, snapshot_every=snapshot_every) as service,
        httpx.Client(base_url=f"{service.url}/api/v1", timeout=10.0) as api,
    ):
        assert _counters(api, "restart")["tasks_outstanding"] == WINDOW - 1
        assert _report(api, "restart", ids) == {"accepted": WINDOW - 1, "duplicates": 1, "expired": 2}


def test_draws_a_full_disk_refused_do_not_count_in_the_window_live_or_after_a_restart(
    db: Path, kuka_space: list[dict[str, Any]], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Workers keep asking for tasks while the disk is full, and each refused draw takes indices. Only
    tasks handed out count in the window: the task whose result waits for the disk stays awaited."""
    monkeypatch.setenv("KC_TASK_WINDOW", str(WINDOW))
    with InProcessService(db) as service, httpx.Client(base_url=f"{service.url}/api/v1", timeout=10.0) as api:
        _create(api, kuka_space, "full")
        waiting = _draw(api, "full", 1)
        service.fill_disk()
        refused = [api.post("/curricula/full/tasks", json={"count": 1024}).status_code for _ in range(3)]
        assert refused == [503] * 3, "the disk was not full"
        service.free_disk()
        later = _draw(api, "full", 1)
        assert int(later[0].rpartition(":")[2]) > WINDOW, "the refused draws took no indices"
        assert _counters(api, "full")["tasks_outstanding"] == 2
    with InProcessService(db) as service, httpx.Client(base_url=f"{service.url}/api/v1", timeout=10.0) as api:
        assert _counters(api, "full")["tasks_outstanding"] == 2
        assert _report(api, "full", waiting + later) == {"accepted": 2, "duplicates": 0, "expired": 0}
        _draw(api, "full", WINDOW + 2)
        assert _counters(api, "full")["tasks_outstanding"] == WINDOW, "the window no longer bounds what is kept"
