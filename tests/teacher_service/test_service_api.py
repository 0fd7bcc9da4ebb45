"""Every endpoint and every documented error, against a real uvicorn process and SQLite file.

The module shares one service; each test works on curricula named after itself.
"""

from __future__ import annotations

import os
import signal
import time
from typing import Any

import httpx
import pytest

from common.kuka.task_space import KUKA_TASK_SPACE


def _create(
    http: httpx.Client,
    name: str,
    space: list[dict[str, Any]],
    teacher: str = "random",
    params: dict[str, Any] | None = None,
    seed: int = 0,
) -> httpx.Response:
    body = {"teacher": teacher, "space": space, "params": params or {}, "seed": seed}
    return http.put(f"/curricula/{name}", json=body)


def _draw(http: httpx.Client, name: str, count: int) -> list[dict[str, Any]]:
    response = http.post(f"/curricula/{name}/tasks", json={"count": count})
    assert response.status_code == 200, response.text
    return response.json()["tasks"]


def _report(http: httpx.Client, name: str, results: list[dict[str, Any]]) -> httpx.Response:
    return http.post(f"/curricula/{name}/results", json={"results": results})


def _counters(http: httpx.Client, name: str) -> dict[str, Any]:
    return http.get(f"/curricula/{name}").json()["counters"]


def _errors(response: httpx.Response) -> list[tuple[tuple[Any, ...], str]]:
    assert response.status_code == 422, response.text
    return [(tuple(error["loc"]), error["msg"]) for error in response.json()["detail"]]


def test_put_creates_then_confirms_an_identical_curriculum_and_refuses_a_different_one(http, kuka_space):
    created = _create(http, "put-a", kuka_space, seed=7)
    assert created.status_code == 201
    info = created.json()
    assert info["name"] == "put-a"
    assert info["config"]["teacher"] == "random" and info["config"]["seed"] == 7
    assert info["config"]["space"] == kuka_space
    assert info["counters"]["tasks_issued"] == 0 and info["counters"]["results_received"] == 0

    again = _create(http, "put-a", kuka_space, seed=7)
    assert again.status_code == 200
    assert again.json()["created_at"] == info["created_at"]

    conflict = _create(http, "put-a", kuka_space, seed=8)
    assert conflict.status_code == 409
    assert "different configuration" in conflict.json()["detail"]


@pytest.mark.parametrize(
    ("change", "where", "says"),
    [
        ({"teacher": "curious"}, ("body",), "expected tags: 'alp-gmm', 'manual', 'random', 'fixed'"),
        ({"seed": -1}, ("body", "random", "seed"), "greater than or equal to 0"),
        ({"space": []}, ("body", "random", "space"), "at least 1"),
        ({"space": [{"name": "x", "low": 1.0, "high": 0.0}]}, ("body", "random"), "low <= high"),
        (
            {"space": [{"name": "x", "low": 0.0, "high": 1.0, "hardest": 2.0}]},
            ("body", "random"),
            "hardest=2.0 outside",
        ),
        ({"space": [{"name": "x", "low": -1.5e308, "high": 1.5e308}]}, ("body", "random"), "overflows"),
        ({"params": {"fit_rate": 5, "typo": 1}, "teacher": "alp-gmm"}, ("body", "alp-gmm", "params", "typo"), "Extra"),
        (
            {"params": {"fit_rate": 0}, "teacher": "alp-gmm"},
            ("body", "alp-gmm", "params", "fit_rate"),
            "greater than or equal to 2",
        ),
        (
            {"params": {"nb_em_init": 10**6}, "teacher": "alp-gmm"},
            ("body", "alp-gmm", "params", "nb_em_init"),
            "less than or equal to 5",
        ),
        (
            {"params": {"buffer_size": 10**12}, "teacher": "alp-gmm"},
            ("body", "alp-gmm", "params", "buffer_size"),
            "less than or equal to 10000",
        ),
        (
            {"params": {"fit_rate": 10**9}, "teacher": "alp-gmm"},
            ("body", "alp-gmm", "params", "fit_rate"),
            "less than or equal to 2000",
        ),
        (
            {"params": {"max_components": 10**6}, "teacher": "alp-gmm"},
            ("body", "alp-gmm", "params", "max_components"),
            "less than or equal to 16",
        ),
        (
            {"params": {"fit_rate": 10**6}, "teacher": "covar-gmm"},
            ("body", "covar-gmm", "params", "fit_rate"),
            "less than or equal to 2000",
        ),
        (
            {"params": {"max_region_size": 10**6}, "teacher": "riac"},
            ("body", "riac", "params", "max_region_size"),
            "less than or equal to 1000",
        ),
        ({"params": {"seed": 3}}, ("body", "random", "params", "seed"), "Extra inputs"),
        ({"extra": True}, ("body", "random", "extra"), "Extra inputs"),
    ],
)
def test_put_explains_what_is_wrong_with_a_curriculum(http, kuka_space, change, where, says):
    body = {"teacher": "random", "space": kuka_space, "params": {}, "seed": 0, **change}
    errors = _errors(http.put("/curricula/put-bad", json=body))
    assert any(loc[: len(where)] == where and says in msg for loc, msg in errors), errors
    assert http.get("/curricula/put-bad").status_code == 404


def test_a_lesson_plan_over_any_space_needs_its_anchors_or_its_lessons(http):
    bare = [{"name": "x", "low": 0.0, "high": 1.0}]
    errors = _errors(_create(http, "put-manual", bare, teacher="manual"))
    assert any("needs the anchors, or give lessons" in msg for _, msg in errors)
    anchored = [{**bare[0], "easiest": 0.0, "hardest": 1.0}]
    assert _create(http, "put-manual", anchored, teacher="manual", params={"steps": 5}).status_code == 201
    assert [task["params"] for task in _draw(http, "put-manual", 2)] == [{"x": 0.0}] * 2
    listed = {"lessons": [{"x": 0.5}, {"x": 0.75}]}
    assert _create(http, "put-manual-listed", bare, teacher="manual", params=listed).status_code == 201
    assert [task["params"] for task in _draw(http, "put-manual-listed", 1)] == [{"x": 0.5}]


def test_curriculum_names_are_checked(http, kuka_space):
    assert _create(http, "bad name!", kuka_space).status_code in (404, 422)
    assert _create(http, "-leading-dash", kuka_space).status_code == 422


def test_list_and_get_show_configuration_and_counters(http, kuka_space):
    _create(http, "list-a", kuka_space)
    _create(http, "list-b", kuka_space, teacher="fixed")
    names = {c["name"]: c for c in http.get("/curricula").json()["curricula"]}
    assert {"list-a", "list-b"} <= set(names)
    assert names["list-b"]["config"]["teacher"] == "fixed"
    one = http.get("/curricula/list-b").json()
    assert one["config"] == names["list-b"]["config"] and one["created_at"] == names["list-b"]["created_at"]
    missing = http.get("/curricula/never-made")
    assert missing.status_code == 404 and "never-made" in missing.json()["detail"]


def test_tasks_lie_in_the_space_and_are_counted(http, kuka_space):
    _create(http, "tasks-a", kuka_space)
    tasks = _draw(http, "tasks-a", 5) + _draw(http, "tasks-a", 3)
    assert len({t["task_id"] for t in tasks}) == 8
    for task in tasks:
        KUKA_TASK_SPACE.validate(task["params"])
    counters = _counters(http, "tasks-a")
    assert counters["tasks_issued"] == 8 and counters["tasks_outstanding"] == 8


@pytest.mark.parametrize("count", [0, 1025, -1])
def test_task_count_is_bounded(http, kuka_space, count):
    _create(http, "tasks-bounds", kuka_space)
    errors = _errors(http.post("/curricula/tasks-bounds/tasks", json={"count": count}))
    assert errors[0][0] == ("body", "count")


def test_tasks_from_an_unknown_curriculum_is_404(http):
    assert http.post("/curricula/nobody/tasks", json={"count": 1}).status_code == 404
    assert http.post("/curricula/nobody/results", json={"results": []}).status_code == 404
    assert http.get("/curricula/nobody/state").status_code == 404


def test_results_are_accepted_once_per_task(http, kuka_space):
    _create(http, "results-a", kuka_space)
    tasks = _draw(http, "results-a", 3)
    results = [
        {"task_id": t["task_id"], "reward": float(i), "success": i == 2, "length": 10 + i} for i, t in enumerate(tasks)
    ]
    assert _report(http, "results-a", results).json() == {"accepted": 3, "duplicates": 0, "expired": 0}
    assert _report(http, "results-a", results).json() == {"accepted": 0, "duplicates": 3, "expired": 0}

    more = _draw(http, "results-a", 1)[0]
    twice = [{"task_id": more["task_id"], "reward": 1.0}] * 2
    assert _report(http, "results-a", twice).json() == {"accepted": 1, "duplicates": 1, "expired": 0}

    counters = _counters(http, "results-a")
    assert counters["results_received"] == 4 and counters["tasks_outstanding"] == 0
    assert counters["results_per_second"] > 0


@pytest.mark.parametrize(
    ("bad_item", "where", "says"),
    [
        ({"task_id": "results-atomic:999999", "reward": 1.0}, "task_id", "never issued"),
        ({"task_id": "other-curriculum:0", "reward": 1.0}, "task_id", "never issued"),
        ({"task_id": "results-atomic:01", "reward": 1.0}, "task_id", "never issued"),
        ({"task_id": "results-atomic:0"}, "reward", "Field required"),
        ({"task_id": "results-atomic:0", "reward": "lots"}, "reward", "valid number"),
        ({"task_id": "results-atomic:0", "reward": 1.0, "length": -3}, "length", "greater than or equal to 0"),
        ({"task_id": "results-atomic:0", "reward": 1.0, "comment": "hi"}, "comment", "Extra inputs"),
    ],
)
def test_one_bad_result_rejects_the_request_and_says_which_and_why(http, kuka_space, bad_item, where, says):
    _create(http, "results-atomic", kuka_space)
    good = _draw(http, "results-atomic", 1)[0]
    received = _counters(http, "results-atomic")["results_received"]
    response = _report(http, "results-atomic", [{"task_id": good["task_id"], "reward": 1.0}, bad_item])
    errors = _errors(response)
    assert any(loc[:3] == ("body", "results", 1) and loc[-1] == where and says in msg for loc, msg in errors), errors
    assert _counters(http, "results-atomic")["results_received"] == received
    assert _report(http, "results-atomic", [{"task_id": good["task_id"], "reward": 1.0}]).json()["accepted"] == 1


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity"])
def test_non_finite_rewards_are_rejected_by_index(http, kuka_space, literal):
    _create(http, "results-finite", kuka_space)
    task = _draw(http, "results-finite", 1)[0]
    body = '{"results": [{"task_id": "%s", "reward": 1.0}, {"task_id": "%s", "reward": %s}]}' % (  # noqa: UP031  JSON's braces would need doubling in an f-string
        task["task_id"],
        task["task_id"],
        literal,
    )
    response = http.post(
        "/curricula/results-finite/results", content=body, headers={"Content-Type": "application/json"}
    )
    errors = _errors(response)
    assert errors == [(("body", "results", 1, "reward"), "Input should be a finite number")]
    assert _counters(http, "results-finite")["results_received"] == 0


def test_state_shows_the_teacher_and_recent_results(http, kuka_space):
    _create(http, "state-a", kuka_space, teacher="fixed")
    tasks = _draw(http, "state-a", 4)
    _report(
        http,
        "state-a",
        [{"task_id": t["task_id"], "reward": i / 2, "success": None, "length": 5} for i, t in enumerate(tasks)],
    )
    state = http.get("/curricula/state-a/state").json()
    assert state["teacher"]["kind"] == "fixed"
    assert state["teacher"]["point"] == KUKA_TASK_SPACE.hardest()
    assert state["curriculum"]["counters"]["results_received"] == 4
    assert [r["reward"] for r in state["recent_results"]] == [0.0, 0.5, 1.0, 1.5]
    assert [r["task_id"] for r in state["recent_results"]] == [t["task_id"] for t in tasks]
    assert state["recent_results"][0]["params"] == KUKA_TASK_SPACE.hardest()
    last_two = http.get("/curricula/state-a/state", params={"recent": 2}).json()["recent_results"]
    assert [r["reward"] for r in last_two] == [1.0, 1.5]


def test_refits_run_while_tasks_keep_being_served(http, kuka_space):
    """A task request made right after the result that triggers a fit is answered before that
    fit finishes, from the previous model. (Each fit is let finish before the next falls due: one
    falling due while the last still waits for a fit process would replace it.)"""
    _create(http, "refit-a", kuka_space, teacher="alp-gmm", params={"fit_rate": 100}, seed=3)
    answered_at = []
    for _ in range(2):
        tasks = _draw(http, "refit-a", 100)
        results = [
            {"task_id": t["task_id"], "reward": 10 * t["params"]["rnd_obj_x"] + 0.1 * i} for i, t in enumerate(tasks)
        ]
        assert _report(http, "refit-a", results).json()["accepted"] == 100
        _draw(http, "refit-a", 1)
        answered_at.append(time.time())
        pending = _counters(http, "refit-a")["fits_pending"]
        assert pending >= 1, "the fit finished before the next request: nothing was overlapped"
        deadline = time.monotonic() + 120
        while _counters(http, "refit-a")["fits_pending"] and time.monotonic() < deadline:
            time.sleep(0.1)
    state = http.get("/curricula/refit-a/state").json()
    fits = state["fits"]
    assert [f["index"] for f in fits] == [0, 1] and not any(f["replayed"] or f["error"] for f in fits)
    for fit, answered in zip(fits, answered_at, strict=True):
        assert answered < fit["finished_at"]
    assert state["curriculum"]["counters"]["last_fit_at"] == fits[-1]["finished_at"]
    assert state["teacher"]["fits"] == 2 and state["teacher"]["components"]


def _wait_for_fits(http: httpx.Client, name: str, fits: int) -> dict[str, Any]:
    deadline = time.monotonic() + 120
    while (counters := _counters(http, name))["fits_completed"] < fits:
        assert time.monotonic() < deadline, f"only {counters['fits_completed']} of {fits} fits finished"
        time.sleep(0.05)
    return counters


def test_fits_carry_on_when_the_fit_process_dies(http, service, kuka_space, fit_processes):
    params = {"fit_rate": 20, "min_components": 2, "max_components": 3}
    _create(http, "fit-crash", kuka_space, teacher="alp-gmm", params=params)
    for fit in range(1, 3):
        tasks = _draw(http, "fit-crash", 20)
        _report(http, "fit-crash", [{"task_id": t["task_id"], "reward": t["params"]["jp2"]} for t in tasks])
        _wait_for_fits(http, "fit-crash", fit)
        (fitter,) = fit_processes(service.pid)
        os.kill(fitter, signal.SIGKILL)
    tasks = _draw(http, "fit-crash", 20)
    _report(http, "fit-crash", [{"task_id": t["task_id"], "reward": t["params"]["jp4"]} for t in tasks])
    assert _wait_for_fits(http, "fit-crash", 3)["fits_pending"] == 0
    fits = http.get("/curricula/fit-crash/state").json()["fits"]
    assert [(f["index"], f["error"]) for f in fits] == [(0, None), (1, None), (2, None)]


def test_healthz_and_prometheus_metrics(http, service, kuka_space):
    _create(http, "metrics-a", kuka_space)
    task = _draw(http, "metrics-a", 1)[0]
    _report(http, "metrics-a", [{"task_id": task["task_id"], "reward": 1.0}])
    health = httpx.get(f"{service.url}/healthz")
    assert health.json()["status"] == "ok" and health.json()["curricula"] >= 1
    metrics = httpx.get(f"{service.url}/metrics")
    assert metrics.headers["content-type"].startswith("text/plain")
    text = metrics.text
    assert 'kc_http_requests_total{method="POST",route="/api/v1/curricula/{name}/tasks",status="200"}' in text
    assert 'kc_results_total{curriculum="metrics-a",outcome="accepted"} 1.0' in text
    assert 'kc_tasks_issued_total{curriculum="metrics-a"} 1.0' in text
    assert "kc_http_request_duration_seconds_bucket" in text and "kc_fit_duration_seconds" in text


def test_oversized_bodies_are_refused(http, service):
    response = http.post(
        "/curricula/anything/results",
        content=b"[" + b" " * (2 << 20) + b"]",
        headers={"Content-Type": "application/json"},
    )
    assert response.status_code == 413


def test_openapi_documents_every_endpoint_and_error(service):
    schema = httpx.get(f"{service.url}/openapi.json").json()
    paths = schema["paths"]
    assert set(paths) >= {
        "/api/v1/curricula",
        "/api/v1/curricula/{name}",
        "/api/v1/curricula/{name}/tasks",
        "/api/v1/curricula/{name}/results",
        "/api/v1/curricula/{name}/state",
        "/healthz",
        "/metrics",
    }
    put = paths["/api/v1/curricula/{name}"]["put"]
    assert {"200", "201", "401", "409", "413", "422"} <= set(put["responses"])
    assert {"401", "404", "413", "422"} <= set(paths["/api/v1/curricula/{name}/results"]["post"]["responses"])
    assert put["security"] == [{"HTTPBearer": []}]
    assert "security" not in paths["/api/v1/curricula/{name}/state"]["get"]


def test_openapi_shows_each_teacher_kinds_parameters_with_bounds_defaults_and_docs(service):
    schemas = httpx.get(f"{service.url}/openapi.json").json()["components"]["schemas"]
    for kind in ("AlpGmm", "Manual", "Random", "Fixed", "Currot"):
        assert schemas[f"{kind}Curriculum"]["properties"]["params"]["$ref"] == f"#/components/schemas/{kind}Params"
    fit_rate = schemas["AlpGmmParams"]["properties"]["fit_rate"]
    assert (fit_rate["minimum"], fit_rate["maximum"], fit_rate["default"]) == (2, 2000, 250)
    assert fit_rate["description"].startswith("Results between two mixture fits")
    window = schemas["ManualParams"]["properties"]["window"]
    assert (window["minimum"], window["maximum"], window["default"]) == (1, 10_000, 100)
    every_field = [
        (kind, name, field)
        for kind in ("AlpGmmParams", "ManualParams", "FixedParams", "CurrotParams")
        for name, field in schemas[kind]["properties"].items()
    ]
    assert all(field.get("description") for _, _, field in every_field), every_field


def test_writes_need_the_token_and_reads_do_not(service, write_token, kuka_space):
    api = f"{service.url}/api/v1"
    body = {"teacher": "random", "space": kuka_space, "params": {}, "seed": 0}
    for headers in ({}, {"Authorization": "Bearer wrong"}, {"Authorization": f"Basic {write_token}"}):
        refused = httpx.put(f"{api}/curricula/auth-a", json=body, headers=headers)
        assert refused.status_code == 401 and refused.headers["www-authenticate"] == "Bearer"
        assert "KC_TEACHER_TOKEN" in refused.json()["detail"]
    good = {"Authorization": f"Bearer {write_token}"}
    assert httpx.put(f"{api}/curricula/auth-a", json=body, headers=good).status_code == 201
    assert httpx.post(f"{api}/curricula/auth-a/tasks", json={"count": 1}).status_code == 401
    task = httpx.post(f"{api}/curricula/auth-a/tasks", json={"count": 1}, headers=good).json()["tasks"][0]
    result = {"results": [{"task_id": task["task_id"], "reward": 1.0}]}
    assert httpx.post(f"{api}/curricula/auth-a/results", json=result).status_code == 401
    assert httpx.post(f"{api}/curricula/auth-a/results", json=result, headers=good).json()["accepted"] == 1
    assert httpx.get(f"{api}/curricula/auth-a").json()["counters"]["results_received"] == 1
    assert httpx.get(f"{api}/curricula/auth-a/state").status_code == 200
    assert httpx.get(f"{api}/curricula").status_code == 200
    assert httpx.get(f"{service.url}/metrics").status_code == 200
