"""The hot endpoints' fast path (``teacher_service.api.hot_routes``) against the framework behind it,
on a real uvicorn over a real SQLite file.

Well-formed draws and reports never reach the framework. Every other request does, and gets the
framework's own answer: each is sent twice, as ``application/json`` (which the fast path may take)
and as ``application/json; charset=utf-8`` (which FastAPI reads the same way and the fast path
always hands over), and both answers must agree in status, headers and body.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from in_process_service import InProcessService
from starlette.types import Receive, Scope, Send

from common.client.schemas import API_PREFIX
from teacher_service.api.hot_routes import HotRoutes

TOKEN = "hot-routes-test-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
FAST = "application/json"
FRAMEWORK_ONLY = "application/json; charset=utf-8"
CURRICULUM = "hot"


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessService]:
    db = tmp_path_factory.mktemp("hot") / "teacher.db"
    with InProcessService(db, TOKEN, allowed_hosts=["127.0.0.1", "teacher.example"]) as running:
        yield running


@pytest.fixture(scope="module")
def http(service: InProcessService, kuka_space: list[dict[str, Any]]) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=f"{service.url}{API_PREFIX}", headers=AUTH, timeout=10.0) as client:
        client.put(f"/curricula/{CURRICULUM}", json={"teacher": "random", "space": kuka_space}).raise_for_status()
        yield client


@pytest.fixture()
def framework_paths(service: InProcessService) -> Iterator[list[str]]:
    """The paths of the HTTP requests that reach the framework behind the fast path."""
    hot = service.app.middleware_stack
    assert isinstance(hot, HotRoutes)
    framework, reached = hot.app, []

    async def watch(scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            reached.append(scope["path"])
        await framework(scope, receive, send)

    hot.app = watch
    yield reached
    hot.app = framework


def post(http: httpx.Client, path: str, body: bytes, content_type: str, **headers: str) -> httpx.Response:
    return http.post(path, content=body, headers={"Content-Type": content_type, **headers})


def draw(http: httpx.Client, count: int) -> list[dict[str, Any]]:
    response = post(http, f"/curricula/{CURRICULUM}/tasks", json.dumps({"count": count}).encode(), FAST)
    response.raise_for_status()
    tasks: list[dict[str, Any]] = response.json()["tasks"]
    return tasks


def results_body(tasks: list[dict[str, Any]]) -> bytes:
    return json.dumps({"results": [{"task_id": t["task_id"], "reward": 1.0, "success": True} for t in tasks]}).encode()


def answer(response: httpx.Response) -> tuple[int, dict[str, str], bytes]:
    return response.status_code, {k: v for k, v in response.headers.items() if k != "date"}, response.content


def test_draws_and_reports_skip_the_framework_and_answer_as_it_does(
    http: httpx.Client, framework_paths: list[str]
) -> None:
    tasks = draw(http, 3)
    path = f"/curricula/{CURRICULUM}/results"
    first = post(http, path, results_body(tasks), FAST)
    assert first.json() == {"accepted": 3, "duplicates": 0, "expired": 0}
    again_fast = post(http, path, results_body(tasks), FAST)
    assert framework_paths == []
    again_framework = post(http, path, results_body(tasks), FRAMEWORK_ONLY)
    assert framework_paths == [f"{API_PREFIX}{path}"]
    assert answer(again_fast) == answer(again_framework)
    assert again_fast.json() == {"accepted": 0, "duplicates": 3, "expired": 0}

    fast_draw = post(http, f"/curricula/{CURRICULUM}/tasks", b'{"count": 2}', FAST)
    framework_draw = post(http, f"/curricula/{CURRICULUM}/tasks", b'{"count": 2}', FRAMEWORK_ONLY)
    assert fast_draw.headers["content-type"] == framework_draw.headers["content-type"] == "application/json"
    assert [sorted(task) for task in fast_draw.json()["tasks"]] == [sorted(t) for t in framework_draw.json()["tasks"]]

    counters = http.get(f"/curricula/{CURRICULUM}").json()["counters"]
    assert counters["results_received"] == 3 and counters["tasks_issued"] == 7
    metrics = httpx.get(f"{http.base_url.scheme}://{http.base_url.netloc.decode()}/metrics").text
    for route, status in (("tasks", 200), ("results", 200)):
        assert f'route="{API_PREFIX}/curricula/{{name}}/{route}",status="{status}"}} ' in metrics
    assert 'kc_results_total{curriculum="hot",outcome="duplicate"} 6.0' in metrics


def _refused_requests(issued: list[dict[str, Any]]) -> dict[str, tuple[str, bytes, dict[str, str]]]:
    """What a careless or hostile client sends the hot endpoints: (path, body, headers)."""
    tasks, results = f"/curricula/{CURRICULUM}/tasks", f"/curricula/{CURRICULUM}/results"
    one = b'{"count": 1}'
    return {
        "no token": (tasks, one, {"Authorization": ""}),
        "a wrong token": (tasks, one, {"Authorization": "Bearer not-the-token-at-all"}),
        "the token in another scheme": (tasks, one, {"Authorization": f"Basic {TOKEN}"}),
        "a host not allowed": (tasks, one, {"Host": "attacker.example"}),
        "JSON cut short": (tasks, b'{"count": 1', {}),
        "no body": (tasks, b"", {}),
        "no tasks": (tasks, b'{"count": 0}', {}),
        "too many tasks": (tasks, b'{"count": 100000}', {}),
        "a field the model lacks": (tasks, b'{"count": 1, "seed": 3}', {}),
        "a count that is text": (tasks, b'{"count": "many"}', {}),
        "a curriculum that does not exist": ("/curricula/nobody/tasks", one, {}),
        "a name the pattern refuses": ("/curricula/no!name/tasks", one, {}),
        "a name ending in a newline": (f"/curricula/{CURRICULUM}%0A/tasks", one, {}),
        "a body over the size limit": (tasks, b" " * (2 << 20) + one, {}),
        "a task never issued": (results, b'{"results": [{"task_id": "hot:999999", "reward": 1.0}]}', {}),
        "a NaN reward": (results, b'{"results": [{"task_id": "hot:0", "reward": NaN}]}', {}),
        "a lone surrogate in a task id": (results, b'{"results": [{"task_id": "hot:\\ud800", "reward": 1.0}]}', {}),
        "too many results": (results, json.dumps({"results": [{"task_id": "x", "reward": 0}] * 1025}).encode(), {}),
        "a duplicate report in UTF-16": (results, results_body(issued).decode().encode("utf-16"), {}),
    }


def test_every_other_request_gets_the_frameworks_own_answer(http: httpx.Client, framework_paths: list[str]) -> None:
    issued = draw(http, 2)
    post(http, f"/curricula/{CURRICULUM}/results", results_body(issued), FAST).raise_for_status()
    differ = {}
    for what, (path, body, headers) in _refused_requests(issued).items():
        framework_paths.clear()
        fast = answer(post(http, path, body, FAST, **headers))
        handed_over = list(framework_paths)
        framework = answer(post(http, path, body, FRAMEWORK_ONLY, **headers))
        if fast != framework:
            differ[what] = (fast, framework)
        if what != "a task never issued":  # refused by the curriculum itself, which the fast path calls
            assert handed_over, f"{what}: the fast path answered it"
    assert not differ, differ
    surrogate = post(http, *_refused_requests(issued)["a lone surrogate in a task id"][:2], FAST)
    assert surrogate.status_code == 422 and "hot:\\ud800" in surrogate.json()["detail"][0]["input"]


def test_a_failure_inside_the_endpoint_is_a_500_as_the_framework_answers_it(
    service: InProcessService, http: httpx.Client
) -> None:
    curriculum = service.app.state.registry.get(CURRICULUM)

    async def broken(count: int) -> list[Any]:
        raise RuntimeError("a bug in a teacher")

    def send(content_type: str) -> httpx.Response:  # on a connection of its own: uvicorn closes it after a 500
        with httpx.Client(base_url=http.base_url, headers=AUTH) as client:
            return post(client, f"/curricula/{CURRICULUM}/tasks", b'{"count": 1}', content_type)

    service.on_loop(lambda: setattr(curriculum, "issue", broken))
    try:
        fast, framework = answer(send(FAST)), answer(send(FRAMEWORK_ONLY))
    finally:
        service.on_loop(lambda: delattr(curriculum, "issue"))
    assert fast == framework
    assert fast[0] == 500 and fast[2] == b"Internal Server Error"
    assert draw(http, 1)


def test_a_chunked_body_is_handed_to_the_framework(http: httpx.Client, framework_paths: list[str]) -> None:
    response = http.post(
        f"/curricula/{CURRICULUM}/tasks",
        content=iter([b'{"count": ', b"2}"]),
        headers={"Content-Type": FAST},
    )
    assert response.status_code == 200 and len(response.json()["tasks"]) == 2
    assert framework_paths == [f"{API_PREFIX}/curricula/{CURRICULUM}/tasks"]
