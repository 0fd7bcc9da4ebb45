"""A service started on a database that another version wrote: a real service on a real SQLite file.

The test stores curricula, then changes the stored rows as a version with other formats would
have left them: a CURROT snapshot whose teacher state lacks an entry today's teacher reads, a
stored fit model that lacks one too, and a curriculum of a teacher kind this version does not
have. The service must still start and serve every curriculum it can: the CURROT one rebuilt from
its first result into the teacher an in-process reference became over the same history, the
unknown kind refused by name with the reason, and the next start served from the new snapshot.
"""

from __future__ import annotations

import json
import sqlite3
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from common.client.schemas import ParameterSpec
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.process import ServiceProcess
from teacher_service.teachers import EpisodeResult, FitJob, make_teacher

SEED = 3
SPACE = [ParameterSpec.from_parameter(p).model_dump() for p in KUKA_TASK_SPACE.parameters]
CURROT = {"particles": 40, "update_every": 12, "buffer_size": 40, "candidates": 8, "delta": 1.0}
REBUILDING = "rebuilding it from its first stored result"


def _as_json(value: Any) -> Any:
    return json.loads(json.dumps(value))


class Mirror:
    """One curriculum on the service and a reference teacher given the same draws and results,
    with each due fit installed on both before more tasks are drawn."""

    def __init__(self, api: httpx.Client, name: str, kind: str, params: dict[str, Any]) -> None:
        self.api, self.name = api, name
        self.reference = make_teacher(kind, KUKA_TASK_SPACE, SEED, params)
        body = {"teacher": kind, "space": SPACE, "params": params, "seed": SEED}
        assert api.put(f"/curricula/{name}", json=body).status_code == 201
        self.due: list[FitJob] = []

    def step(self, count: int) -> None:
        tasks = self.api.post(f"/curricula/{self.name}/tasks", json={"count": count}).json()["tasks"]
        assert [t["params"] for t in tasks] == _as_json(self.reference.sample(count))
        results = [{"task_id": t["task_id"], "reward": 2.0 * t["params"]["jp2"]} for t in tasks]
        assert self.api.post(f"/curricula/{self.name}/results", json={"results": results}).json()["accepted"] == count
        for task, result in zip(tasks, results, strict=True):
            if (job := self.reference.learn(EpisodeResult(task["params"], result["reward"]))) is not None:
                self.due.append(job)
        deadline = time.monotonic() + 60.0
        while self.api.get(f"/curricula/{self.name}").json()["counters"]["fits_pending"]:
            assert time.monotonic() < deadline, "fits did not finish"
            time.sleep(0.05)
        while self.due:
            self.reference.install(self.due.pop(0).run())

    def teacher_state(self) -> Any:
        return self.api.get(f"/curricula/{self.name}/state").json()["teacher"]


@pytest.fixture
def service(tmp_path: Path) -> Iterator[ServiceProcess]:
    service = ServiceProcess(tmp_path / "teacher.db", env={"KC_SNAPSHOT_EVERY": "10"})
    yield service
    service.stop()


def _as_another_version_left_it(db: Path) -> None:
    """The CURROT snapshot's state without ``pending``, fit 0's model without ``why``, and the
    curriculum ``retired`` of a kind this version lacks."""
    with sqlite3.connect(db) as connection:
        (curriculum_id,) = connection.execute("SELECT id FROM curricula WHERE name = 'particles'").fetchone()
        (teacher,) = connection.execute(
            "SELECT teacher FROM snapshots WHERE curriculum_id = ?", (curriculum_id,)
        ).fetchone()
        snapshot = json.loads(teacher)
        del snapshot["state"]["pending"]
        connection.execute(
            "UPDATE snapshots SET teacher = ? WHERE curriculum_id = ?", (json.dumps(snapshot), curriculum_id)
        )
        (stored,) = connection.execute(
            "SELECT model FROM fits WHERE curriculum_id = ? AND fit_index = 0", (curriculum_id,)
        ).fetchone()
        model = json.loads(stored)
        del model["why"]
        connection.execute(
            "UPDATE fits SET model = ? WHERE curriculum_id = ? AND fit_index = 0", (json.dumps(model), curriculum_id)
        )
        (spec,) = connection.execute("SELECT spec FROM curricula WHERE name = 'retired'").fetchone()
        connection.execute(
            "UPDATE curricula SET spec = ? WHERE name = 'retired'",
            (json.dumps({**json.loads(spec), "teacher": "retired-kind"}),),
        )


def _history_chunks(db: Path, name: str) -> list[tuple[int, int]]:
    with sqlite3.connect(db) as connection:
        return connection.execute(
            "SELECT first_row, row_count FROM history_chunks JOIN curricula ON id = curriculum_id"
            " WHERE name = ? ORDER BY first_row",
            (name,),
        ).fetchall()


def test_a_database_from_another_version_starts_and_serves_what_it_can(service: ServiceProcess) -> None:
    service.start()
    with httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0) as api:
        particles = Mirror(api, "particles", "currot", CURROT)
        other = Mirror(api, "other", "random", {})
        Mirror(api, "retired", "random", {}).step(4)
        for _ in range(5):
            particles.step(8)  # fits fall due at results 12, 24 and 36
            other.step(8)
        assert particles.teacher_state()["fits"] >= 2
        service.kill()
        _as_another_version_left_it(service.db)

        service.start()
        assert service.log_path.read_text().count(REBUILDING) == 1
        chunks = _history_chunks(service.db, "particles")
        assert [first for first, _ in chunks] == [0] and chunks[0][1] == 40, "the rebuild's rows replace the old"
        assert particles.teacher_state() == _as_json(particles.reference.state())
        fits = api.get("/curricula/particles/state").json()["fits"]
        assert [f["error"] for f in fits if f["index"] == 0] == [None]
        assert other.teacher_state() == _as_json(other.reference.state())
        assert [c["name"] for c in api.get("/curricula").json()["curricula"]] == ["particles", "other"]
        for request in (
            api.get("/curricula/retired"),
            api.post("/curricula/retired/tasks", json={"count": 1}),
            api.put("/curricula/retired", json={"teacher": "random", "space": SPACE}),
        ):
            assert request.status_code == 409
            detail = request.json()["detail"]
            assert "'retired'" in detail and "'retired-kind' is not in this version" in detail
        fresh = api.put("/curricula/fresh", json={"teacher": "random", "space": SPACE})
        assert fresh.status_code == 201
        particles.step(8)
        other.step(8)

        service.kill()
        service.start()  # from the snapshot the rebuild stored, and those after it
        assert service.log_path.read_text().count(REBUILDING) == 1
        assert particles.teacher_state() == _as_json(particles.reference.state())
        particles.step(8)
        assert particles.teacher_state() == _as_json(particles.reference.state())


def test_a_registration_sent_again_after_an_upgrade_that_added_parameters_joins_the_same_curriculum(
    service: ServiceProcess,
) -> None:
    """A curriculum stored by a version before ``estimate`` and ``recent_results`` (CURROT's) and before
    parameter types: the same request a client sent then, sent again to today's service, is the same
    curriculum (200), not a 409; so is today's request with the new parameters at their defaults."""
    old_request = {"teacher": "currot", "space": SPACE, "params": CURROT, "seed": SEED}
    with service, httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0) as api:
        assert api.put("/curricula/older", json=old_request).status_code == 201
    with sqlite3.connect(service.db) as connection:
        (spec,) = connection.execute("SELECT spec FROM curricula WHERE name = 'older'").fetchone()
        stored = json.loads(spec)
        for added in ("estimate", "recent_results"):
            del stored["params"][added]
        for parameter in stored["space"]:
            del parameter["type"]
        connection.execute("UPDATE curricula SET spec = ? WHERE name = 'older'", (json.dumps(stored),))
    with service, httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0) as api:
        again = api.put("/curricula/older", json=old_request)
        assert again.status_code == 200, again.text
        defaults = {
            **CURROT,
            "estimate": "buffers",
            "recent_results": again.json()["config"]["params"]["recent_results"],
        }
        assert api.put("/curricula/older", json={**old_request, "params": defaults}).status_code == 200
        changed = api.put("/curricula/older", json={**old_request, "params": {**CURROT, "estimate": "recent"}})
        assert changed.status_code == 409, "a real difference still conflicts"
