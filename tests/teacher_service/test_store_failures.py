"""A database that refuses writes makes the service answer 503 with the reason, never hang.

The service runs in this process (a real uvicorn on a free port, serving the real app over a real
SQLite file) so that failures can be injected into its store on its own event loop: a full disk
through SQLite's ``max_page_count``, and exceptions that are not SQLite's from the connection.
"""

from __future__ import annotations

import asyncio
import logging
import sqlite3
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
import pytest
from in_process_service import ANSWER_WITHIN_S, InProcessService

from common.client.schemas import ResultAck, ResultBatch
from common.client.teacher_client import Backoff, TeacherClient
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.store import RETRY_S, StoreError

TOKEN = "store-failure-test-token"


class FailingConnection:
    """The store's SQLite connection, except that the next statement starting with ``prefix``
    raises ``failure`` instead of running: once, or with ``lasting`` every time until ``failure``
    is set to None."""

    def __init__(self, db: sqlite3.Connection, prefix: str, failure: BaseException, lasting: bool = False) -> None:
        self.db = db
        self.prefix = prefix
        self.failure: BaseException | None = failure
        self.lasting = lasting

    def _check(self, sql: str) -> None:
        if self.failure is not None and sql.startswith(self.prefix):
            failure = self.failure
            if not self.lasting:
                self.failure = None
            raise failure

    def execute(self, sql: str, *args: Any) -> sqlite3.Cursor:
        self._check(sql)
        return self.db.execute(sql, *args)

    def executemany(self, sql: str, *args: Any) -> sqlite3.Cursor:
        self._check(sql)
        return self.db.executemany(sql, *args)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.db, name)


@pytest.fixture
def service(tmp_path: Path) -> Iterator[InProcessService]:
    with InProcessService(tmp_path / "teacher.db", TOKEN) as running:
        yield running


@pytest.fixture
def http(service: InProcessService) -> Iterator[httpx.Client]:
    headers = {"Authorization": f"Bearer {TOKEN}"}
    with httpx.Client(base_url=f"{service.url}/api/v1", headers=headers, timeout=ANSWER_WITHIN_S) as client:
        yield client


def _create(http: httpx.Client, name: str, kuka_space: list[dict[str, Any]]) -> None:
    response = http.put(f"/curricula/{name}", json={"teacher": "random", "space": kuka_space, "seed": 0})
    assert response.status_code == 201, response.text


def _draw(http: httpx.Client, name: str, count: int) -> httpx.Response:
    return http.post(f"/curricula/{name}/tasks", json={"count": count})


def _results(tasks: list[dict[str, Any]]) -> dict[str, Any]:
    return {"results": [{"task_id": task["task_id"], "reward": 1.0, "success": True} for task in tasks]}


def _refused(response: httpx.Response, reason: str) -> None:
    assert response.status_code == 503, response.text
    assert response.json()["detail"] == f"the teacher's database could not store this request: {reason}"
    assert int(response.headers["Retry-After"]) > 0


def _stored_results(db: Path, name: str) -> set[str]:
    with sqlite3.connect(db) as connection:
        rows = connection.execute(
            "SELECT r.task_index FROM results r JOIN curricula c ON c.id = r.curriculum_id WHERE c.name = ?", (name,)
        )
        return {f"{name}:{index}" for (index,) in rows}


def test_a_full_disk_answers_503_with_the_reason_and_writes_resume_once_there_is_room(
    service: InProcessService, http: httpx.Client, kuka_space: list[dict[str, Any]]
) -> None:
    _create(http, "full", kuka_space)
    acknowledged = _draw(http, "full", 1000).json()["tasks"]
    assert http.post("/curricula/full/results", json=_results(acknowledged[:20])).json()["accepted"] == 20

    service.fill_disk()  # never below the current size
    # A thousand tasks, or results, need new pages, and there is no room for them.
    _refused(_draw(http, "full", 1024), "database or disk is full")
    refused_results = http.post("/curricula/full/results", json=_results(acknowledged[20:]))
    _refused(refused_results, "database or disk is full")

    health = http.get(f"{service.url}/healthz")
    assert health.status_code == 200, "alive: a restart would not make room"
    assert (health.json()["status"], health.json()["writes_failing"]) == ("degraded", "database or disk is full")
    assert http.get("/curricula/full").json()["counters"]["results_received"] == 20

    service.free_disk()
    assert len(_draw(http, "full", 1024).json()["tasks"]) == 1024
    assert http.get(f"{service.url}/healthz").json()["status"] == "ok", "recovered by itself at the next write"
    retried = http.post("/curricula/full/results", json=_results(acknowledged[20:])).json()
    assert retried == {"accepted": 980, "duplicates": 0, "expired": 0}, (
        "the refused results were not kept as outstanding"
    )

    assert _stored_results(service.store.path, "full") == {task["task_id"] for task in acknowledged}


def test_a_result_sent_again_while_its_first_write_is_in_flight_waits_for_that_write(
    service: InProcessService, http: httpx.Client, kuka_space: list[dict[str, Any]]
) -> None:
    """A client that timed out sends the same result again while the service is still storing the
    first copy, and that commit fails (the disk filled): the second copy must not be acknowledged as
    a duplicate of a result that was never stored; it is stored itself, once."""
    _create(http, "again", kuka_space)
    tasks = _draw(http, "again", 1).json()["tasks"]
    results = ResultBatch.model_validate(_results(tasks)).results
    curriculum = service.app.state.registry.get("again")
    database = service.store._db
    full = sqlite3.OperationalError("database or disk is full")
    service.on_loop(lambda: setattr(service.store, "_db", FailingConnection(database, "COMMIT", full)))

    async def in_one_round() -> list[Any]:
        return await asyncio.gather(curriculum.report(results), curriculum.report(results), return_exceptions=True)

    first, second = asyncio.run_coroutine_threadsafe(in_one_round(), service.loop).result(ANSWER_WITHIN_S)
    assert isinstance(first, StoreError), first
    assert second == ResultAck(accepted=1, duplicates=0, expired=0), "acknowledged before anything was stored"
    assert _stored_results(service.store.path, "again") == {tasks[0]["task_id"]}
    assert http.post("/curricula/again/results", json=_results(tasks)).json()["duplicates"] == 1


@pytest.mark.parametrize(
    ("prefix", "failure"),
    [
        ("COMMIT", RuntimeError("injected at commit")),
        ("BEGIN", MemoryError("injected at begin")),
        ("INSERT INTO results", ValueError("injected in a write")),
    ],
)
def test_an_exception_that_is_not_sqlites_fails_the_writes_and_the_next_ones_work(
    service: InProcessService,
    http: httpx.Client,
    kuka_space: list[dict[str, Any]],
    prefix: str,
    failure: BaseException,
) -> None:
    _create(http, "odd", kuka_space)
    tasks = _draw(http, "odd", 10).json()["tasks"]
    database = service.store._db
    service.on_loop(lambda: setattr(service.store, "_db", FailingConnection(database, prefix, failure)))

    _refused(http.post("/curricula/odd/results", json=_results(tasks)), f"{type(failure).__name__}: {failure}")
    assert http.get(f"{service.url}/healthz").status_code == 200

    assert http.post("/curricula/odd/results", json=_results(tasks)).json() == {
        "accepted": 10,
        "duplicates": 0,
        "expired": 0,
    }
    assert len(_draw(http, "odd", 5).json()["tasks"]) == 5
    assert _stored_results(service.store.path, "odd") == {task["task_id"] for task in tasks}


def test_a_failure_that_lasts_is_logged_when_it_starts_and_when_it_ends_not_at_every_write(
    service: InProcessService, http: httpx.Client, kuka_space: list[dict[str, Any]], caplog: pytest.LogCaptureFixture
) -> None:
    """A refused fit record is tried again every second (``RETRY_S``): a traceback each time would bury the
    log of a long full disk."""
    caplog.set_level(logging.INFO, logger="teacher_service.store")
    _create(http, "lasting", kuka_space)
    tasks = _draw(http, "lasting", 4).json()["tasks"]
    full = sqlite3.OperationalError("database or disk is full")
    refusing = FailingConnection(service.store._db, "COMMIT", full, lasting=True)  # as a disk that stays full
    service.on_loop(lambda: setattr(service.store, "_db", refusing))
    for task in tasks[:3]:
        _refused(http.post("/curricula/lasting/results", json=_results([task])), "database or disk is full")
    failures = [record for record in caplog.records if record.getMessage().startswith("commit of")]
    assert len(failures) == 1 and failures[0].exc_info, "each failed commit logged its traceback again"

    refusing.failure = None
    assert http.post("/curricula/lasting/results", json=_results(tasks)).json()["accepted"] == 4
    assert caplog.messages.count("writes land again (they had failed: database or disk is full)") == 1


def test_every_write_of_a_failed_group_is_answered(service: InProcessService, kuka_space: list[dict[str, Any]]) -> None:
    """Writes that arrive together share one commit; when it fails, each of them gets its 503."""
    headers = {"Authorization": f"Bearer {TOKEN}"}
    with httpx.Client(base_url=f"{service.url}/api/v1", headers=headers, timeout=ANSWER_WITHIN_S) as setup:
        names = [f"group-{i}" for i in range(8)]
        for name in names:
            _create(setup, name, kuka_space)
    database = service.store._db
    service.on_loop(lambda: setattr(service.store, "_db", FailingConnection(database, "COMMIT", OSError("i/o"))))

    def draw(name: str) -> int:
        with httpx.Client(base_url=f"{service.url}/api/v1", headers=headers, timeout=ANSWER_WITHIN_S) as client:
            return _draw(client, name, 1).status_code

    with ThreadPoolExecutor(len(names)) as pool:
        statuses = list(pool.map(draw, names))
    assert 503 in statuses, "the injected failure never met a write"
    assert set(statuses) <= {200, 503}
    with httpx.Client(base_url=f"{service.url}/api/v1", headers=headers, timeout=ANSWER_WITHIN_S) as after:
        assert all(_draw(after, name, 1).status_code == 200 for name in names)


def test_the_client_keeps_results_through_503s_and_delivers_them_once_there_is_room(
    service: InProcessService, kuka_space: list[dict[str, Any]], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="common.client.teacher_client")
    with TeacherClient(service.url, "client", token=TOKEN, prefetch=1000, backoff=Backoff(0.01, 0.2)) as client:
        client.register("random", KUKA_TASK_SPACE)
        assignments = [client.next_task() for _ in range(1000)]
        service.fill_disk()
        for assignment in assignments:
            client.report(assignment, reward=1.0)
        assert not client.flush(timeout=2.0)
        assert client.pending == 1000 and client.delivered == 0
        assert "HTTP 503: the teacher's database could not store this request: database or disk is full" in caplog.text

        service.free_disk()
        assert client.flush(timeout=30)
        assert client.delivered == 1000
    assert _stored_results(service.store.path, "client") == {a.task_id for a in assignments}


FITTING = {"teacher": "alp-gmm", "seed": 0, "params": {"fit_rate": 200}}


def _fit_during_a_full_disk(
    service: InProcessService, http: httpx.Client, kuka_space: list[dict[str, Any]]
) -> dict[str, Any]:
    """Make a fit due, fill the disk while it runs, and wait for it to be installed: its record is
    refused. Returns the curriculum's live state."""
    assert http.put("/curricula/fitting", json={**FITTING, "space": kuka_space}).status_code == 201
    tasks = _draw(http, "fitting", 200).json()["tasks"]
    assert http.post("/curricula/fitting/results", json=_results(tasks)).json()["accepted"] == 200  # fit 0 due
    service.fill_disk()
    while http.get("/curricula/fitting").json()["counters"]["fits_pending"]:
        time.sleep(0.05)
    assert _stored_fits(service.store.path) == 0, "the disk had room for the fit's record"
    live = http.get("/curricula/fitting/state").json()
    assert [fit["index"] for fit in live["fits"]] == [0] and live["fits"][0]["error"] is None
    return live


def _stored_fits(db: Path) -> int:
    with sqlite3.connect(db) as connection:
        return int(connection.execute("SELECT COUNT(*) FROM fits").fetchone()[0])


def test_a_fit_record_the_full_disk_refused_lands_once_there_is_room_with_no_other_write(
    tmp_path: Path, kuka_space: list[dict[str, Any]]
) -> None:
    """Nobody waits for a fit's record, so nothing else would send it again: the store does, until
    it lands. Without it a replay from the first result finds the fit due and never recorded, and
    every later fit stuck behind it (the chaos run's "state equals a replay" caught this)."""
    headers = {"Authorization": f"Bearer {TOKEN}"}
    with (
        InProcessService(tmp_path / "teacher.db", TOKEN) as service,
        httpx.Client(base_url=f"{service.url}/api/v1", headers=headers) as http,
    ):
        _fit_during_a_full_disk(service, http, kuka_space)
        time.sleep(2 * RETRY_S)
        assert _stored_fits(service.store.path) == 0, "stored while the disk was full"
        service.free_disk()
        deadline = time.monotonic() + 10 * RETRY_S
        while _stored_fits(service.store.path) == 0:
            assert time.monotonic() < deadline, "the refused fit record was never tried again"
            time.sleep(0.05)
        assert http.get("/curricula/fitting").json()["counters"]["fits_completed"] == 1
        assert _stored_fits(service.store.path) == 1, "stored more than once"


def test_a_fit_whose_record_the_disk_still_refused_at_the_stop_is_run_again_by_the_restart(
    tmp_path: Path, kuka_space: list[dict[str, Any]]
) -> None:
    """The service stops while the disk is still full: the fit's record is lost. The restart runs
    that fit again from the stored results, and is the same teacher."""
    db = tmp_path / "teacher.db"
    headers = {"Authorization": f"Bearer {TOKEN}"}
    with (
        InProcessService(db, TOKEN) as service,
        httpx.Client(base_url=f"{service.url}/api/v1", headers=headers) as http,
    ):
        live = _fit_during_a_full_disk(service, http, kuka_space)
    assert _stored_fits(db) == 0, "the full disk took the record at the stop"

    with (
        InProcessService(db, TOKEN) as service,
        httpx.Client(base_url=f"{service.url}/api/v1", headers=headers) as http,
    ):
        while http.get("/curricula/fitting").json()["counters"]["fits_pending"]:
            time.sleep(0.05)
        restarted = http.get("/curricula/fitting/state").json()
        assert restarted["teacher"] == live["teacher"], "the restart ran the lost fit again, to the same model"
        assert restarted["fits"][0]["replayed"] is True
        assert http.get(f"{service.url}/healthz").json()["status"] == "ok"
