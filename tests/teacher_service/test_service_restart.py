"""Crash safety: a service killed with SIGKILL and restarted on its database is the same teacher.

The expected state comes from a teacher built in-process with the same kind, space, seed and
parameters, driven through the same history: tasks drawn while a fit is running come from the old
model on both, and the fit is installed afterwards. The live service matches it draw by draw, and
so must the restarted one: same counters, same fitted components and per-task bookkeeping, same
next tasks, including when a fit was still running at the kill.
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from common.client.schemas import ParameterSpec
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.process import ServiceProcess
from teacher_service.teachers import EpisodeResult, FitJob, make_teacher

NAME = "crash"
SEED = 11
KIND_PARAMS: dict[str, dict[str, Any]] = {
    "alp-gmm": {"fit_rate": 16, "min_components": 2, "max_components": 4},
    "currot": {"particles": 30, "update_every": 16, "buffer_size": 32, "candidates": 8},
}
"""Per kind, parameters that make a fit fall due every 16 results."""


def _reward(params: dict[str, float], index: int) -> float:
    return 10.0 * (1.0 - params["rnd_obj_x"]) * params["jp2"] + 0.01 * index


def _as_json(value: Any) -> Any:
    return json.loads(json.dumps(value))


class Mirror:
    """Drives the service and an in-process reference teacher through the same history."""

    def __init__(self, api: httpx.Client, kind: str, params: dict[str, Any]) -> None:
        self.api = api
        self.reference = make_teacher(kind, KUKA_TASK_SPACE, SEED, params)
        self.due: list[FitJob] = []
        self.reported: list[dict[str, Any]] = []

    def draw(self, count: int) -> list[dict[str, Any]]:
        tasks = self.api.post(f"/curricula/{NAME}/tasks", json={"count": count}).json()["tasks"]
        assert [t["params"] for t in tasks] == _as_json(self.reference.sample(count))
        return tasks

    def report(self, tasks: list[dict[str, Any]]) -> None:
        results = [
            {"task_id": t["task_id"], "reward": _reward(t["params"], len(self.reported) + i), "length": 50}
            for i, t in enumerate(tasks)
        ]
        assert self.api.post(f"/curricula/{NAME}/results", json={"results": results}).json()["accepted"] == len(tasks)
        for task, result in zip(tasks, results, strict=True):
            job = self.reference.learn(EpisodeResult(task["params"], result["reward"], None, 50))
            if job is not None:
                self.due.append(job)
        self.reported += results

    def counters(self) -> dict[str, Any]:
        return self.api.get(f"/curricula/{NAME}").json()["counters"]

    def finish_fits(self, timeout: float = 60.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while (counters := self.counters())["fits_pending"]:
            assert time.monotonic() < deadline, "fits did not finish"
            time.sleep(0.05)
        while self.due:
            self.reference.install(self.due.pop(0).run())
        return counters


@pytest.mark.parametrize("kind", sorted(KIND_PARAMS))
def test_sigkill_then_restart_gives_the_same_teacher(tmp_path, fit_processes, kind):
    space = [ParameterSpec.from_parameter(p).model_dump() for p in KUKA_TASK_SPACE.parameters]
    service = ServiceProcess(tmp_path / "teacher.db").start()
    try:
        api = httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0)
        assert (
            api.put(
                f"/curricula/{NAME}", json={"teacher": kind, "space": space, "params": KIND_PARAMS[kind], "seed": SEED}
            ).status_code
            == 201
        )
        mirror = Mirror(api, kind, KIND_PARAMS[kind])
        mirror.report(mirror.draw(8))
        mirror.report(mirror.draw(8))  # result 16: fit 0 falls due (and starts the fit process)
        drawn_during_fit = mirror.draw(8)
        assert mirror.counters()["fits_pending"] == 1, "these tasks must come from the model before fit 0"
        mirror.finish_fits()
        mirror.report(drawn_during_fit)
        mirror.report(mirror.draw(8))  # result 32: fit 1
        mirror.finish_fits()
        unreported = mirror.draw(3)
        # A warm process can finish a small fit before the next request, so it is paused: fit 2
        # is then surely still running when the service dies.
        (fitter,) = fit_processes(service.pid)
        os.kill(fitter, signal.SIGSTOP)
        try:
            mirror.report(mirror.draw(8))
            mirror.report(mirror.draw(8))  # result 48: fit 2, still running when the service dies
            before = mirror.counters()
            assert before["fits_pending"] == 1
            service.kill()
        finally:
            os.kill(fitter, signal.SIGCONT)
        deadline = time.monotonic() + 30
        while Path(f"/proc/{fitter}").exists():
            assert time.monotonic() < deadline, "the fit process outlived the killed service"
            time.sleep(0.1)
        service.start()

        after = mirror.finish_fits()
        for counter in ("tasks_issued", "results_received", "tasks_outstanding"):
            assert after[counter] == before[counter]
        assert after["fits_completed"] == mirror.reference.state()["fits"] == 3
        state = api.get(f"/curricula/{NAME}/state").json()
        assert state["teacher"] == _as_json(mirror.reference.state())
        assert [(fit["index"], fit["replayed"]) for fit in state["fits"]] == [(0, True), (1, True), (2, True)]
        assert [r["reward"] for r in state["recent_results"]] == [r["reward"] for r in mirror.reported]

        mirror.draw(5)
        late = [{"task_id": t["task_id"], "reward": 1.0} for t in unreported]
        again = [{"task_id": r["task_id"], "reward": r["reward"]} for r in mirror.reported[:2]]
        assert api.post(f"/curricula/{NAME}/results", json={"results": late + again}).json() == {
            "accepted": 3,
            "duplicates": 2,
            "expired": 0,
        }
        api.close()
    finally:
        service.stop()


def test_sigkill_then_restart_gives_the_same_learnability_teacher(tmp_path):
    """A kind without fits: its pool is refreshed inline, every 16 results here, from the last 40;
    the restart rebuilds it from a snapshot (every 20 results) and the results after it."""
    space = [ParameterSpec.from_parameter(p).model_dump() for p in KUKA_TASK_SPACE.parameters]
    params = {"pool_size": 30, "update_every": 16, "buffer_size": 40, "top_k": 8}
    service = ServiceProcess(tmp_path / "teacher.db", env={"KC_SNAPSHOT_EVERY": "20"}).start()
    try:
        api = httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0)
        spec = {"teacher": "learnability", "space": space, "params": params, "seed": SEED}
        assert api.put(f"/curricula/{NAME}", json=spec).status_code == 201
        mirror = Mirror(api, "learnability", params)
        for _ in range(9):
            mirror.report(mirror.draw(7))  # 63 results: 3 pools, the oldest results out of the window
        unreported = mirror.draw(3)
        before = mirror.counters()
        assert mirror.reference.state()["refreshes"] == 3
        service.kill()
        service.start()

        after = mirror.counters()
        for counter in ("tasks_issued", "results_received", "tasks_outstanding"):
            assert after[counter] == before[counter]
        state = api.get(f"/curricula/{NAME}/state").json()
        assert state["teacher"] == _as_json(mirror.reference.state())
        mirror.report(unreported)
        mirror.report(mirror.draw(10))  # the next pool, refreshed after the restart, matches too
        assert api.get(f"/curricula/{NAME}/state").json()["teacher"] == _as_json(mirror.reference.state())
        api.close()
    finally:
        service.stop()
