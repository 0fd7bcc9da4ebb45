"""ADR and SPDL behind a real service: the tasks it hands out match an in-process teacher fed the
same results, its state shows their bounds and Gaussian, and after SIGKILL and a restart on the
same database it is the same teacher with the same next tasks."""

from __future__ import annotations

import json
from typing import Any

import httpx

from common.client.schemas import ParameterSpec
from common.client.task_space import Parameter, TaskSpace
from teacher_service.process import ServiceProcess
from teacher_service.teachers import EpisodeResult, Teacher, make_teacher

SPACE = TaskSpace(
    [
        Parameter("x", 0.0, 1.0, easiest=0.0, hardest=1.0),
        Parameter("y", -2.0, 2.0, easiest=2.0, hardest=-2.0),
    ]
)
SEED = 4
PARAMS: dict[str, dict[str, Any]] = {
    "adr": {"queue_length": 4},
    "self-paced": {"update_every": 20, "kl_limit": 0.5},
}


def _succeeds(task: dict[str, float], episode: int) -> bool:
    """Tasks within a reach from the easiest corner succeed; the reach grows with the episodes."""
    reach = 0.1 + episode / 400
    return max(task["x"], (2.0 - task["y"]) / 4.0) <= reach


def _drive(api: httpx.Client, kind: str, reference: Teacher) -> None:
    """Draw batches of tasks from the service and report the scripted outcomes to both teachers."""
    episode = 0
    for batch in range(25):
        tasks = api.post(f"/curricula/{kind}/tasks", json={"count": 1 + batch % 7}).json()["tasks"]
        assert [t["params"] for t in tasks] == reference.sample(len(tasks))
        results = []
        for task in tasks:
            success = _succeeds(task["params"], episode)
            results.append({"task_id": task["task_id"], "reward": float(success), "success": success})
            reference.learn_and_fit(EpisodeResult(task["params"], float(success), success))
            episode += 1
        assert api.post(f"/curricula/{kind}/results", json={"results": results}).json()["accepted"] == len(tasks)


def test_served_teachers_match_in_process_and_survive_sigkill(tmp_path) -> None:
    references = {kind: make_teacher(kind, SPACE, SEED, params) for kind, params in PARAMS.items()}
    space = [ParameterSpec.from_parameter(p).model_dump() for p in SPACE.parameters]
    service = ServiceProcess(tmp_path / "teacher.db").start()
    try:
        api = httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0)
        states = {}
        for kind, reference in references.items():
            body = {"teacher": kind, "space": space, "params": PARAMS[kind], "seed": SEED}
            assert api.put(f"/curricula/{kind}", json=body).status_code == 201
            _drive(api, kind, reference)
            states[kind] = api.get(f"/curricula/{kind}/state").json()["teacher"]
            assert states[kind] == json.loads(json.dumps(reference.state()))
            assert states[kind]["moves"], "the teacher has moved: the restart must restore learned state"
        assert states["adr"]["bounds"]["high"]["x"] > 0.0
        assert states["self-paced"]["components"][0]["mean"]["x"] > 0.0

        service.kill()
        service.start()
        for kind, reference in references.items():
            assert api.get(f"/curricula/{kind}/state").json()["teacher"] == states[kind]
            tasks = api.post(f"/curricula/{kind}/tasks", json={"count": 9}).json()["tasks"]
            assert [t["params"] for t in tasks] == reference.sample(9)
        api.close()
    finally:
        service.stop()
