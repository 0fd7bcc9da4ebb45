"""Restart from snapshots: a real service on a real SQLite file, killed with SIGKILL and started again.

Each test drives the service and an in-process reference teacher through the same history (fits
are awaited before more tasks are drawn, so both install them at the same point). The restarted
service must be the reference teacher: same state, same next tasks; it must not run an installed
fit again (no fit process starts), and it must rebuild the teacher from the snapshot plus the
results stored after it, not from the whole history: the tests alter the stored rewards the
snapshot covers, which a full replay would pick up.
"""

from __future__ import annotations

import json
import math
import sqlite3
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from common.client.schemas import ParameterSpec
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.process import ServiceProcess
from teacher_service.store import SCHEMA_VERSION
from teacher_service.teachers import EpisodeResult, FitJob, Teacher, make_teacher

SEED = 5
KIND_PARAMS: dict[str, dict[str, Any]] = {
    # Ties everywhere (a third of the tasks are the hardest task) and tree switches every 8 results.
    "alp-gmm": {"fit_rate": 16, "max_components": 3, "target_task_ratio": 0.3, "buffer_size": 8},
    "manual": {"threshold": 0.5, "window": 5, "min_episodes": 5},
    "random": {},
    "fixed": {},
    "covar-gmm": {"fit_rate": 16, "max_components": 3},
    "riac": {"max_region_size": 12},
    "adr": {"queue_length": 3, "reward_range": [0.0, 2.0]},
    "self-paced": {"update_every": 12, "reward_range": [0.0, 2.0]},
    "currot": {"particles": 40, "update_every": 12, "buffer_size": 40, "candidates": 8, "delta": 1.0},
    "learnability": {"pool_size": 30, "update_every": 12, "buffer_size": 40, "top_k": 8},
}
SPACE = [ParameterSpec.from_parameter(p).model_dump() for p in KUKA_TASK_SPACE.parameters]


def _reward(params: dict[str, float], index: int) -> float:
    return 1.0 + 0.4 * math.sin(3.0 * params["jp2"] + index)


def _as_json(value: Any) -> Any:
    return json.loads(json.dumps(value))


class Mirror:
    """One curriculum on the service, and a reference teacher given the same draws and results.
    Every step is logged, so ``replay`` can build the reference again with some fits left out."""

    def __init__(self, api: httpx.Client, name: str, kind: str, params: dict[str, Any] | None = None) -> None:
        self.api, self.name, self.kind = api, name, kind
        self.params = KIND_PARAMS[kind] if params is None else params
        self.reference = self.fresh_reference()
        self.due: list[FitJob] = []
        self.reported = 0
        self.results: list[dict[str, Any]] = []
        self.steps: list[tuple[str, Any]] = []

    def fresh_reference(self) -> Teacher:
        return make_teacher(self.kind, KUKA_TASK_SPACE, SEED, self.params)

    def create(self) -> None:
        body = {"teacher": self.kind, "space": SPACE, "params": self.params, "seed": SEED}
        assert self.api.put(f"/curricula/{self.name}", json=body).status_code == 201

    def draw(self, count: int) -> list[dict[str, Any]]:
        reply = self.api.post(f"/curricula/{self.name}/tasks", json={"count": count})
        tasks: list[dict[str, Any]] = reply.json()["tasks"]
        assert [t["params"] for t in tasks] == _as_json(self.reference.sample(count))
        self.steps.append(("draw", count))
        return tasks

    def report(self, tasks: list[dict[str, Any]]) -> None:
        results = [
            {"task_id": t["task_id"], "reward": _reward(t["params"], self.reported + i)} for i, t in enumerate(tasks)
        ]
        ack = self.api.post(f"/curricula/{self.name}/results", json={"results": results}).json()
        assert ack["accepted"] == len(tasks)
        for task, result in zip(tasks, results, strict=True):
            self.learn(task["params"], result["reward"])
        self.reported += len(tasks)
        self.results += results
        self.finish_fits()

    def learn(self, task: dict[str, float], reward: float) -> None:
        """What the reference does for a result the service accepted."""
        if (job := self.reference.learn(EpisodeResult(task, reward))) is not None:
            self.due.append(job)
        self.steps.append(("result", EpisodeResult(task, reward)))

    def counters(self) -> dict[str, Any]:
        counters: dict[str, Any] = self.api.get(f"/curricula/{self.name}").json()["counters"]
        return counters

    def state(self) -> dict[str, Any]:
        state: dict[str, Any] = self.api.get(f"/curricula/{self.name}/state").json()
        return state

    def finish_fits(self, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while self.counters()["fits_pending"]:
            assert time.monotonic() < deadline, "fits did not finish"
            time.sleep(0.05)
        while self.due:
            job = self.due.pop(0)
            self.reference.install(job.run())
            self.steps.append(("install", job.index))

    def replay(self, left_out: set[int]) -> Teacher:
        """The reference again, with the fits in ``left_out`` never installed."""
        teacher = self.fresh_reference()
        jobs: dict[int, FitJob] = {}
        for step, value in self.steps:
            if step == "draw":
                teacher.sample(value)
            elif step == "result":
                if (job := teacher.learn(value)) is not None:
                    jobs[job.index] = job
            elif value not in left_out:
                teacher.install(jobs[value].run())
        return teacher


@pytest.fixture
def api_for() -> Iterator[Callable[[ServiceProcess], httpx.Client]]:
    clients: list[httpx.Client] = []

    def connect(service: ServiceProcess) -> httpx.Client:
        clients.append(httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0))
        return clients[-1]

    yield connect
    for client in clients:
        client.close()


def _drop_covered_results(db: Path, name: str) -> int:
    """Delete every stored result the curriculum's snapshot covers, which a restart must not need;
    returns how many results were stored after it (the tail a restart replays)."""
    with sqlite3.connect(db) as connection:
        curriculum_id, last_seq = connection.execute(
            "SELECT c.id, s.last_seq FROM snapshots s JOIN curricula c ON c.id = s.curriculum_id WHERE c.name = ?",
            (name,),
        ).fetchone()
        assert last_seq > 0, "no snapshot was stored while the service ran"
        connection.execute("DELETE FROM results WHERE curriculum_id = ? AND seq <= ?", (curriculum_id, last_seq))
        tail: int = connection.execute(
            "SELECT count(*) FROM results WHERE curriculum_id = ?", (curriculum_id,)
        ).fetchone()[0]
    return tail


@pytest.mark.parametrize("kind", sorted(KIND_PARAMS))
def test_a_killed_service_restarts_from_its_snapshot_as_the_same_teacher(
    kind: str, tmp_path: Path, api_for: Callable[[ServiceProcess], httpx.Client], fit_processes: Any
) -> None:
    service = ServiceProcess(tmp_path / "teacher.db", env={"KC_SNAPSHOT_EVERY": "10"}).start()
    try:
        mirror = Mirror(api_for(service), "snap", kind)
        mirror.create()
        for _ in range(7):
            mirror.report(mirror.draw(8))
        unreported = mirror.draw(3)
        before = mirror.counters()
        fits_before = mirror.state()["fits"]
        learned = {"alp-gmm": ("fits", 3), "manual": ("lesson", 2)}
        if kind in learned:
            entry, least = learned[kind]
            assert mirror.reference.state()[entry] >= least, "the history must teach the teacher something"

        service.kill()
        tail = _drop_covered_results(service.db, "snap")
        assert 0 < tail < mirror.reported, "the restart must have results to replay"
        service.start()

        assert fit_processes(service.pid) == [], "a restart must not run installed fits again"
        after = mirror.counters()
        for counter in ("tasks_issued", "results_received", "tasks_outstanding", "fits_completed", "last_fit_at"):
            assert after[counter] == before[counter], counter
        state = mirror.state()
        assert state["teacher"] == _as_json(mirror.reference.state())
        assert [(f["index"], f["started_at"], f["error"]) for f in state["fits"]] == [
            (f["index"], f["started_at"], f["error"]) for f in fits_before
        ]
        assert all(f["replayed"] for f in state["fits"])
        assert [r["reward"] for r in state["recent_results"]] == [r["reward"] for r in mirror.results[-tail:]]

        mirror.report(mirror.draw(6))
        late = [{"task_id": t["task_id"], "reward": 1.0} for t in unreported]
        assert mirror.api.post("/curricula/snap/results", json={"results": late}).json() == {
            "accepted": 3,
            "duplicates": 0,
            "expired": 0,
        }
        for task in unreported:
            mirror.learn(task["params"], 1.0)
        mirror.draw(10)
        mirror.finish_fits()  # alp-gmm: result 64 brought fit 3, run live as usual
        assert mirror.state()["teacher"] == _as_json(mirror.reference.state())
    finally:
        service.stop()


def test_a_restart_reads_only_the_history_rows_the_teacher_still_needs(
    tmp_path: Path, api_for: Callable[[ServiceProcess], httpx.Client]
) -> None:
    """ALP-GMM searches the last ``history_window`` results for nearest tasks; once the store has
    written older rows the teacher drops them, and a restart reads only the rows it kept: the test
    deletes the stored chunks before them."""
    params = {"fit_rate": 1000, "max_components": 3, "history_window": 10_000, "buffer_size": 500}
    service = ServiceProcess(tmp_path / "teacher.db", env={"KC_SNAPSHOT_EVERY": "500"}).start()
    try:
        mirror = Mirror(api_for(service), "windowed", "alp-gmm", params)
        mirror.create()
        for _ in range(14):
            mirror.report(mirror.draw(1000))
        mirror.report(mirror.draw(600))
        service.kill()
        with sqlite3.connect(service.db) as connection:
            (teacher,) = connection.execute("SELECT teacher FROM snapshots").fetchone()
            kept_from = Teacher.history_kept_from(json.loads(teacher))
            assert kept_from > 0
            dropped = connection.execute(
                "DELETE FROM history_chunks WHERE first_row + row_count <= ?", (kept_from,)
            ).rowcount
        assert dropped > 0, "chunks before the kept rows were stored"
        service.start()
        assert mirror.state()["teacher"] == _as_json(mirror.reference.state())
        for _ in range(2):
            mirror.report(mirror.draw(700))
        assert mirror.state()["teacher"] == _as_json(mirror.reference.state())
    finally:
        service.stop()


def test_a_restart_installs_stored_models_and_leaves_failed_fits_out(
    tmp_path: Path, api_for: Callable[[ServiceProcess], httpx.Client]
) -> None:
    """Fits are installed from the models in their rows, never fitted again: the test alters a
    stored model's AIC table, which the teacher reports and a refit would restore. The fit runner
    may drop a fit (superseded, over its time limit): its row has an error and no model, and a
    restart that replays past it must not install it."""
    service = ServiceProcess(tmp_path / "teacher.db", env={"KC_SNAPSHOT_EVERY": "1000"}).start()
    try:
        mirror = Mirror(api_for(service), "dropped", "alp-gmm")
        mirror.create()
        for _ in range(5):
            mirror.report(mirror.draw(8))  # fits 0 and 1 installed at results 16 and 32
        mirror.draw(2)
        service.kill()
        with sqlite3.connect(service.db) as connection:
            connection.execute("UPDATE fits SET error = 'superseded by fit 2', model = NULL WHERE fit_index = 1")
            (stored,) = connection.execute("SELECT model FROM fits WHERE fit_index = 0").fetchone()
            model = json.loads(stored)
            model["aic_by_components"] = [[k, aic + 1000.0] for k, aic in model["aic_by_components"]]
            connection.execute("UPDATE fits SET model = ? WHERE fit_index = 0", (json.dumps(model),))
        service.start()

        state = mirror.state()
        assert state["teacher"]["aic_by_components"] == {str(k): aic for k, aic in model["aic_by_components"]}
        assert [(f["index"], f["error"]) for f in state["fits"]] == [(0, None), (1, "superseded by fit 2")]
        mirror.reference = mirror.replay(left_out={1})
        expected = _as_json(mirror.reference.state())
        assert {**state["teacher"], "aic_by_components": None} == {**expected, "aic_by_components": None}
        assert state["teacher"]["fits"] == 1 and state["teacher"]["last_fit_index"] == 0
        mirror.draw(20)
    finally:
        service.stop()


VERSION_1_SCHEMA = """
CREATE TABLE curricula (
    id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE, spec TEXT NOT NULL, created_at REAL NOT NULL
);
CREATE TABLE tasks (
    curriculum_id INTEGER NOT NULL REFERENCES curricula(id), task_index INTEGER NOT NULL, params TEXT NOT NULL,
    results_seen INTEGER NOT NULL, issued_at REAL NOT NULL, PRIMARY KEY (curriculum_id, task_index)
) WITHOUT ROWID;
CREATE TABLE results (
    seq INTEGER PRIMARY KEY, curriculum_id INTEGER NOT NULL, task_index INTEGER NOT NULL, reward REAL NOT NULL,
    success INTEGER, length INTEGER, received_at REAL NOT NULL, UNIQUE (curriculum_id, task_index),
    FOREIGN KEY (curriculum_id, task_index) REFERENCES tasks(curriculum_id, task_index)
);
CREATE TABLE fits (
    curriculum_id INTEGER NOT NULL REFERENCES curricula(id), fit_index INTEGER NOT NULL,
    tasks_sampled INTEGER NOT NULL, results_seen INTEGER NOT NULL, started_at REAL NOT NULL,
    finished_at REAL NOT NULL, error TEXT, PRIMARY KEY (curriculum_id, fit_index)
) WITHOUT ROWID;
PRAGMA user_version = 1;
"""
"""The schema the service wrote before snapshots: no fit models, no snapshots, no history chunks."""


def _version_1_database(path: Path, name: str, teacher: Teacher, batches: int) -> None:
    """What a version-1 service would have stored for ``teacher`` after ``batches`` rounds of eight
    tasks and their results, fits installed as they fell due; three more tasks are left outstanding."""
    spec = {"teacher": teacher.kind, "space": SPACE, "params": KIND_PARAMS[teacher.kind], "seed": SEED}
    with sqlite3.connect(path) as connection:
        connection.executescript(VERSION_1_SCHEMA)
        connection.execute("INSERT INTO curricula VALUES (1, ?, ?, 1.0)", (name, json.dumps(spec)))
        reported = 0
        for batch in range(batches + 1):
            first = teacher.tasks_drawn
            tasks = teacher.sample(8 if batch < batches else 3)
            connection.executemany(
                "INSERT INTO tasks VALUES (1, ?, ?, ?, ?)",
                # issued now: tasks issued longer ago than KC_TASK_TTL_S are no longer awaited after a restart
                [(first + i, json.dumps(task), teacher.results_seen, time.time()) for i, task in enumerate(tasks)],
            )
            if batch == batches:
                break
            for i, task in enumerate(tasks):
                reward = _reward(task, reported)
                connection.execute(
                    "INSERT INTO results (curriculum_id, task_index, reward, success, length, received_at)"
                    " VALUES (1, ?, ?, NULL, 50, ?)",
                    (first + i, reward, 2.5 + batch),
                )
                reported += 1
                if (job := teacher.learn(EpisodeResult(task, reward, None, 50))) is not None:
                    teacher.install(job.run())
                    connection.execute(
                        "INSERT INTO fits VALUES (1, ?, ?, ?, ?, ?, NULL)",
                        (job.index, teacher.tasks_drawn, teacher.results_seen, 3.0 + job.index, 3.5 + job.index),
                    )


def test_a_version_1_database_is_migrated_replayed_once_and_then_restarts_from_a_snapshot(
    tmp_path: Path, api_for: Callable[[ServiceProcess], httpx.Client], fit_processes: Any
) -> None:
    db = tmp_path / "teacher.db"
    mirror_reference = make_teacher("alp-gmm", KUKA_TASK_SPACE, SEED, KIND_PARAMS["alp-gmm"])
    _version_1_database(db, "old", mirror_reference, batches=7)  # 56 results: fits at 16, 32 and 48
    service = ServiceProcess(db).start()
    try:
        mirror = Mirror(api_for(service), "old", "alp-gmm")
        mirror.reference = mirror_reference
        with sqlite3.connect(db) as connection:
            assert connection.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
            models = connection.execute("SELECT fit_index, model IS NOT NULL FROM fits ORDER BY fit_index").fetchall()
            assert models == [(0, 1), (1, 1), (2, 1)], "the first start stores the models of the fits it ran"
            assert connection.execute("SELECT results_seen FROM snapshots").fetchall() == [(56,)]
        state = mirror.state()
        assert state["teacher"] == _as_json(mirror.reference.state())
        assert [(f["index"], f["started_at"], f["replayed"]) for f in state["fits"]] == [
            (0, 3.0, True),
            (1, 4.0, True),
            (2, 5.0, True),
        ]
        assert mirror.counters()["tasks_outstanding"] == 3

        service.kill()
        _drop_covered_results(db, "old")
        service.start()
        assert fit_processes(service.pid) == []
        assert mirror.state()["teacher"] == _as_json(mirror.reference.state())
        mirror.report(mirror.draw(8))
        assert mirror.state()["teacher"] == _as_json(mirror.reference.state())
    finally:
        service.stop()
