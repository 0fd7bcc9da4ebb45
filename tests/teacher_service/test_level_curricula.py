"""Level curricula through a real service: tasks say which episodes are for scoring only, results
carry a bounded score that the teacher learns from and the database keeps, and a killed service comes
back as the same teacher."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import httpx
import pytest

from teacher_service.process import ServiceProcess

LEVELS = [{"name": "level", "type": "integer", "low": 0, "high": 49}]


def play(http: httpx.Client, name: str, rounds: int) -> list[dict[str, object]]:
    """Draw 10 tasks a round and report each with a score that grows with its level."""
    issued: list[dict[str, object]] = []
    for _ in range(rounds):
        tasks = http.post(f"/curricula/{name}/tasks", json={"count": 10}).json()["tasks"]
        results = [
            {"task_id": task["task_id"], "reward": 1.0, "success": True, "score": task["params"]["level"] / 49}
            for task in tasks
        ]
        assert http.post(f"/curricula/{name}/results", json={"results": results}).json()["accepted"] == 10
        issued += tasks
    return issued


def test_robust_plr_marks_new_levels_score_only_and_learns_from_scores(http: httpx.Client) -> None:
    created = http.put("/curricula/robust", json={"teacher": "plr", "space": LEVELS, "params": {"robust": True}})
    assert created.status_code == 201, created.text
    issued = play(http, "robust", 12)
    assert all(isinstance(task["params"]["level"], int) for task in issued)  # type: ignore[index]
    assert issued[0]["score_only"] is True and not any(task["score_only"] for task in issued[-20:])
    state = http.get("/curricula/robust/state").json()
    teacher = state["teacher"]
    assert teacher["scored_levels"] == 50 and teacher["levels"][0]["level"] == 49, "the top score is replayed most"
    assert state["recent_results"][-1]["score"] is not None


@pytest.mark.parametrize(
    ("result", "field"),
    [
        ({"reward": 1.0, "score": "NaN"}, "score"),
        ({"reward": 1.0, "score": 1e13}, "score"),
        ({"reward": 1.0, "scor": 0.5}, "scor"),
    ],
)
def test_a_bad_score_is_a_422_naming_it_and_nothing_is_stored(
    http: httpx.Client, result: dict[str, object], field: str
) -> None:
    http.put("/curricula/bad-score", json={"teacher": "plr", "space": LEVELS})
    task = http.post("/curricula/bad-score/tasks", json={"count": 1}).json()["tasks"][0]
    fields = ", ".join(f'"{key}": {value}' for key, value in result.items())
    body = f'{{"results": [{{"task_id": "{task["task_id"]}", {fields}}}]}}'  # NaN is not JSON: sent as text
    response = http.post("/curricula/bad-score/results", content=body, headers={"Content-Type": "application/json"})
    assert response.status_code == 422 and field in response.text, response.text
    assert http.get("/curricula/bad-score").json()["counters"]["results_received"] == 0


def test_a_space_over_the_level_cap_is_a_422_and_nothing_is_stored(http: httpx.Client) -> None:
    wide = [
        {"name": "seed", "type": "integer", "low": 0, "high": 999},
        {"name": "layout", "type": "integer", "low": 0, "high": 10},
    ]
    response = http.put("/curricula/too-wide", json={"teacher": "learning-progress", "space": wide})
    assert response.status_code == 422 and "holds 11,000 levels" in response.text, response.text
    assert http.get("/curricula/too-wide").status_code == 404


@pytest.mark.parametrize("kind", ["plr", "learning-progress", "learnability"])
def test_a_killed_service_restarts_as_the_same_level_teacher(tmp_path: Path, kind: str) -> None:
    db = tmp_path / "teacher.db"
    with ServiceProcess(db, env={"KC_SNAPSHOT_EVERY": "30"}) as service:
        with httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0) as http:
            assert http.put("/curricula/levels", json={"teacher": kind, "space": LEVELS, "seed": 3}).status_code == 201
            play(http, "levels", 7)  # a snapshot at 30 and 60, results after it to replay
            before = http.get("/curricula/levels/state").json()["teacher"]
        service.kill()
    with sqlite3.connect(db) as connection:
        scores = connection.execute("SELECT score FROM results ORDER BY seq").fetchall()
    assert len(scores) == 70 and all(score is not None for (score,) in scores), "each result's score is stored"
    with ServiceProcess(db) as service, httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0) as http:
        assert http.get("/curricula/levels/state").json()["teacher"] == before
