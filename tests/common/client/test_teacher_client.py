"""The teacher client against a real service process: batching, outages, restarts and errors.

The module shares one service (tests that kill it start it again); each test has its own curriculum.
"""

from __future__ import annotations

import http.server
import json
import logging
import os
import signal
import sqlite3
import threading
import time
from collections.abc import Iterator

import httpx
import numpy as np
import pytest

from common.client.task_space import Parameter, TaskSpace
from common.client.teacher_client import (
    RESULT_LOG_VARIABLE,
    Assignment,
    Backoff,
    TeacherClient,
    TeacherRequestError,
    TeacherUnavailable,
)
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.process import ServiceProcess, free_port

FAST_RETRIES = Backoff(base_s=0.01, cap_s=0.2)
TOKEN = "client-test-token"


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServiceProcess]:
    with ServiceProcess(tmp_path_factory.mktemp("client") / "teacher.db", env={"KC_TEACHER_TOKEN": TOKEN}) as running:
        yield running


def _client(service: ServiceProcess, curriculum: str, token: str = TOKEN, **options) -> TeacherClient:
    return TeacherClient(service.url, curriculum, token=token, backoff=FAST_RETRIES, **options)


def _counters(service: ServiceProcess, curriculum: str) -> dict:
    return httpx.get(f"{service.url}/api/v1/curricula/{curriculum}").json()["counters"]


def test_register_draw_and_report(service):
    with _client(service, "basic", prefetch=4) as client:
        info = client.register("random", KUKA_TASK_SPACE, seed=5)
        assert info.config.teacher == "random" and info.counters.tasks_issued == 0
        assert client.register("random", KUKA_TASK_SPACE, seed=5).created_at == info.created_at
        with pytest.raises(TeacherRequestError) as conflict:
            client.register("random", KUKA_TASK_SPACE, seed=6)
        assert conflict.value.status == 409 and "different configuration" in str(conflict.value)

        first = client.next_task()
        assert not first.offline and KUKA_TASK_SPACE.validate(first.params) == first.params
        assert _counters(service, "basic")["tasks_issued"] == 4, "one request fetches a prefetch batch"
        assignments = [first] + [client.next_task() for _ in range(39)]
        assert len({a.task_id for a in assignments}) == 40

        def report(share: list[Assignment]) -> None:
            for assignment in share:
                client.report(assignment, reward=assignment.params["rnd_obj_x"], success=False, length=7)

        threads = [threading.Thread(target=report, args=(assignments[i::4],)) for i in range(4)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        assert client.flush(timeout=30)
        assert client.pending == 0 and client.delivered == 40
        assert client.info().counters.results_received == 40
        recent = client.state(recent=5).recent_results
        assert [r.task_id for r in recent] == [r.task_id for r in client.state().recent_results[-5:]]
    counters = _counters(service, "basic")
    assert counters["results_received"] == 40 and counters["tasks_outstanding"] == 0


def test_level_tasks_say_score_only_and_results_carry_a_score(service):
    levels = TaskSpace([Parameter("level", 0, 19, type="integer")])
    with _client(service, "robust-levels", prefetch=8) as client:
        client.register("plr", levels, params={"robust": True}, seed=1)
        first = client.next_task()
        assert first.score_only and isinstance(first.params["level"], int), "nothing scored: explore, score only"
        client.report(first, reward=1.0, success=True, score=0.25)
        with pytest.raises(ValueError, match="score must be finite"):
            client.report(first, reward=1.0, score=float("nan"))
        assert client.flush(timeout=30)
        (result,) = client.state(recent=1).recent_results
        assert (result.task_id, result.score) == (first.task_id, 0.25)


def test_no_result_is_lost_across_a_service_restart(service):
    with _client(service, "restart", prefetch=16) as client:
        client.register("random", KUKA_TASK_SPACE)
        assignments = [client.next_task() for _ in range(16)]
        for assignment in assignments[:6]:
            client.report(assignment, reward=1.0)
        assert client.flush(timeout=30)

        service.kill()
        for assignment in assignments[6:]:
            client.report(assignment, reward=2.0)
        assert not client.flush(timeout=0.5)
        assert client.pending == 10

        service.start()
        assert client.flush(timeout=30)
        assert client.delivered == 16
    state = httpx.get(f"{service.url}/api/v1/curricula/restart/state").json()
    assert state["curriculum"]["counters"]["results_received"] == 16
    assert sorted(r["task_id"] for r in state["recent_results"]) == sorted(a.task_id for a in assignments)


def test_an_outage_longer_than_the_buffer_drops_the_oldest_results_and_says_so_once(service, caplog):
    caplog.set_level(logging.WARNING, logger="common.client.teacher_client")
    with _client(service, "bounded", prefetch=40, max_buffered_results=10) as client:
        client.register("random", KUKA_TASK_SPACE)
        assignments = [client.next_task() for _ in range(40)]
        service.kill()
        for reward, assignment in enumerate(assignments):
            client.report(assignment, reward=float(reward))
        assert client.pending == 10 and client.dropped_results == 30
        assert not client.flush(timeout=0.5)

        service.start()
        assert client.flush(timeout=30)
        assert client.delivered == 10 and client.dropped_results == 30
    state = httpx.get(f"{service.url}/api/v1/curricula/bounded/state").json()
    delivered = {result["task_id"]: result["reward"] for result in state["recent_results"]}
    newest = assignments[-10:]
    assert delivered == {a.task_id: float(reward) for reward, a in enumerate(assignments) if a in newest}
    drops = [record.getMessage() for record in caplog.records if "dropp" in record.getMessage()]
    assert len(drops) == 2, drops
    assert "the most this client keeps" in drops[0] and "30 results were dropped" in drops[1]


def test_a_full_buffer_keeps_the_newest_while_a_batch_is_on_its_way(service):
    """With the teacher hanging mid-delivery: the batch on its way is delivered, and of the rest the newest stay."""
    with _client(service, "bounded-in-flight", prefetch=30, max_buffered_results=10) as client:
        client.register("random", KUKA_TASK_SPACE)
        assignments = [client.next_task() for _ in range(30)]
        os.kill(service.pid, signal.SIGSTOP)
        try:
            client.report(assignments[0], reward=1.0)
            time.sleep(0.5)  # the sender has taken it as a batch of its own and waits for an answer
            for assignment in assignments[1:]:
                client.report(assignment, reward=2.0)
            assert client.pending == 10 and client.dropped_results == 20
        finally:
            os.kill(service.pid, signal.SIGCONT)
        assert client.flush(timeout=30)
    state = httpx.get(f"{service.url}/api/v1/curricula/bounded-in-flight/state").json()
    delivered = sorted(result["task_id"] for result in state["recent_results"])
    assert delivered == sorted(a.task_id for a in assignments[:1] + assignments[-9:])


def test_offline_assignments_keep_a_worker_busy_while_the_teacher_is_down(service):
    with _client(service, "offline", prefetch=3, task_timeout=1.0) as client:
        client.register("random", KUKA_TASK_SPACE)
        issued = [client.next_task() for _ in range(3)]
        service.kill()
        waited = time.monotonic()
        offline = [client.next_task()]
        assert time.monotonic() - waited > 0.5, "the first miss keeps retrying for most of task_timeout"
        waited = time.monotonic()
        offline += [client.next_task() for _ in range(3)]
        assert time.monotonic() - waited < 0.5, "later misses do not wait again"
        assert all(a.offline for a in offline)
        assert [a.params for a in offline] == [issued[0].params, issued[1].params, issued[2].params, issued[0].params]
        client.report(offline[0], reward=3.0)
        assert client.offline_results == 1 and client.pending == 0

        service.start()
        back = client.next_task()
        assert not back.offline
        client.report(back, reward=1.0)
        assert client.flush(timeout=30)
    assert _counters(service, "offline")["results_received"] == 1


def _result_requests(service: ServiceProcess) -> float:
    """POST .../results requests the service has answered with 200, from its Prometheus metrics."""
    wanted = 'kc_http_requests_total{method="POST",route="/api/v1/curricula/{name}/results",status="200"} '
    lines = httpx.get(f"{service.url}/metrics").text.splitlines()
    return sum(float(line.removeprefix(wanted)) for line in lines if line.startswith(wanted))


@pytest.mark.parametrize("report_interval", [0.0, 5.0])
def test_a_report_interval_gathers_results_and_flush_does_not_wait_for_it(service, report_interval):
    curriculum = f"gathered-{report_interval:g}"
    with _client(service, curriculum, prefetch=20, report_interval=report_interval) as client:
        client.register("random", KUKA_TASK_SPACE)
        before = _result_requests(service)
        for assignment in [client.next_task() for _ in range(20)]:
            client.report(assignment, reward=1.0)
            time.sleep(0.02)
        started = time.monotonic()
        assert client.flush(timeout=30)
        assert time.monotonic() - started < 2.0, "a flush does not wait out the interval"
        requests = _result_requests(service) - before
    assert _counters(service, curriculum)["results_received"] == 20
    if report_interval:
        assert requests <= 2, "the first result alone, then the other 19 together"
    else:
        assert requests >= 5, "without an interval, results go out as they come"


def test_no_task_at_all_is_an_error_not_a_hang():
    with (
        TeacherClient(f"http://127.0.0.1:{free_port()}", "kuka", task_timeout=0.3, backoff=FAST_RETRIES) as client,
        pytest.raises(TeacherUnavailable, match="none issued before"),
    ):
        client.next_task()


def test_invalid_results_are_dropped_and_the_rest_delivered(service):
    with _client(service, "invalid") as client:
        client.register("random", KUKA_TASK_SPACE)
        good = client.next_task()
        client.report(Assignment("invalid:999999", good.params), reward=1.0)
        client.report(good, reward=1.0)
        assert client.flush(timeout=30)
        assert client.rejected == 1 and client.delivered == 1
        with pytest.raises(ValueError, match="finite"):
            client.report(good, reward=float("nan"))
    assert _counters(service, "invalid")["results_received"] == 1


def test_errors_retrying_cannot_fix_are_raised(service):
    with _client(service, "refused", token="wrong") as client:
        with pytest.raises(TeacherRequestError) as refused:
            client.register("random", KUKA_TASK_SPACE)
        assert refused.value.status == 401
    with _client(service, "ghost") as client:
        with pytest.raises(TeacherRequestError) as missing:
            client.next_task()
        assert missing.value.status == 404 and "ghost" in str(missing.value)
        client.report(Assignment("ghost:0", KUKA_TASK_SPACE.hardest()), reward=0.0)
        with pytest.raises(TeacherRequestError, match="404"):
            client.flush(timeout=30)
        assert client.pending == 1, "an undeliverable result is kept, not silently dropped"
        assert client.close(timeout=0.1) == 1


def test_the_service_decides_which_teacher_kinds_exist(service):
    """The client checks only that a kind is a well-formed name, so it needs no change when the
    service gains a kind; the service refuses one it lacks with a 422 naming the kinds it has."""
    with _client(service, "unknown-kind") as client:
        with pytest.raises(TeacherRequestError) as unknown:
            client.register("no-such-kind", KUKA_TASK_SPACE)
        assert unknown.value.status == 422 and "alp-gmm" in str(unknown.value)
        with pytest.raises(ValueError, match="teacher"):
            client.register("Not A Kind!", KUKA_TASK_SPACE)


def test_a_service_killed_between_storing_results_and_answering_keeps_each_result_once(tmp_path):
    """Results flow without pause while the service is SIGKILLed and restarted, until a kill lands
    after a batch was stored but before its answer reached the client (the client then resends it
    and the service says it already had it): every reported result is stored exactly once."""
    service = ServiceProcess(tmp_path / "teacher.db")
    service.start()
    stop, reported = threading.Event(), []
    client = _client(service, "killed-mid-answer", token=None, prefetch=64, report_interval=0.0, task_timeout=0.3)
    client.register("random", KUKA_TASK_SPACE, seed=2)

    def play() -> None:
        while not stop.is_set():
            assignment = client.next_task()
            if not assignment.offline:
                client.report(assignment, reward=1.0)
                reported.append(assignment.task_id)

    player = threading.Thread(target=play)
    player.start()
    rng = np.random.default_rng(0)
    try:
        for kills in range(1, 41):
            time.sleep(float(rng.uniform(0.05, 0.4)))
            service.kill()
            service.start()
            if kills >= 3 and client.already_stored:
                break
    finally:
        stop.set()
        player.join()
    assert client.flush(timeout=60)
    client.close()
    service.stop()
    assert client.already_stored > 0, f"no kill in {kills} landed between a stored batch and its answer"
    with sqlite3.connect(tmp_path / "teacher.db") as connection:
        stored = connection.execute("SELECT COUNT(*), COUNT(DISTINCT task_index) FROM results").fetchone()
    assert stored == (len(reported), len(set(reported))) and len(reported) == len(set(reported))


class _FullDiskThenAck(http.server.BaseHTTPRequestHandler):
    """A stand-in service: its first two result deliveries get the 503 of a full disk, then an ack."""

    refusals = 2

    def do_POST(self) -> None:  # noqa: N802 (http.server's name)
        body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
        if type(self).refusals:
            type(self).refusals -= 1
            status, answer = 503, {"detail": "the teacher's database could not store this request: disk is full"}
        else:
            status, answer = 200, {"accepted": len(body["results"]), "duplicates": 0, "expired": 0}
        payload = json.dumps(answer).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(payload)))
        self.end_headers()
        self.wfile.write(payload)

    def log_message(self, *args: object) -> None:
        pass


def test_the_opt_in_delivery_log_names_each_acknowledged_task_and_each_5xx(tmp_path, monkeypatch):
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _FullDiskThenAck)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_port}"
    monkeypatch.delenv(RESULT_LOG_VARIABLE, raising=False)
    try:
        with TeacherClient(url, "quiet", backoff=FAST_RETRIES) as quiet:
            quiet.report(Assignment("quiet:0", {}), reward=1.0)
            assert quiet.flush(timeout=30)
        assert list(tmp_path.iterdir()) == [], "no log unless one is asked for"

        log_file = tmp_path / "delivered.jsonl"
        monkeypatch.setenv(RESULT_LOG_VARIABLE, str(log_file))
        _FullDiskThenAck.refusals = 2
        with TeacherClient(url, "logged", backoff=FAST_RETRIES) as client:
            for index in range(3):
                client.report(Assignment(f"logged:{index}", {}), reward=1.0)
            assert client.flush(timeout=30)
    finally:
        server.shutdown()
        server.server_close()
    records = [json.loads(line) for line in log_file.read_text().splitlines()]
    refused = [record for record in records if "status" in record]
    assert [(r["status"], r["method"], r["curriculum"]) for r in refused] == [(503, "POST", "logged")] * 2
    assert all("disk is full" in r["detail"] for r in refused)
    acknowledged = [task for record in records for task in record.get("acknowledged", [])]
    assert sorted(acknowledged) == ["logged:0", "logged:1", "logged:2"]
    assert all(record["pid"] == os.getpid() for record in records)
