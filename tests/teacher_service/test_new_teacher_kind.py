"""Adding a teacher kind is one module and its line in the registry: a copy of the packages gains a toy
kind that way, and a real service of the copy lists it, checks its parameters, teaches with it and
restores it after a restart."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from teacher_service.process import ServiceProcess
from tests.package_copies import changed_files, copies_before_and_after

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("common", "teacher_service")
REGISTRY = Path("teacher_service/teachers/__init__.py")
TOY_MODULE = Path("teacher_service/teachers/toy.py")

TOY_SOURCE = '''"""A toy kind for the registry test: tasks uniform in a centred share of the box."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from pydantic import Field

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms
from teacher_service.teachers.params import TeacherParams
from teacher_service.teachers.state import ARRAY, OPTIONAL_FLOAT, StateField


class ToyParams(TeacherParams):
    spread: float = Field(default=0.5, ge=0.0, le=1.0)
    """Share of the box, around its centre, that tasks come from."""


class ToyTeacher(Teacher):
    """Tasks uniform in a centred share of the box; remembers the best return, and per quarter of
    the first parameter (as a level teacher would per level) the results, the best and whether any
    return reached 10."""

    kind = "toy"
    Params = ToyParams
    params: ToyParams
    state_fields = (
        StateField("best", OPTIONAL_FLOAT),
        StateField("results", ARRAY),
        StateField("bests", ARRAY),
        StateField("reached", ARRAY),
    )

    def __init__(self, space: TaskSpace, seed: int, params: ToyParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        self.best: float | None = None
        self.results = np.zeros(4, dtype=np.int64)
        self.bests = np.full(4, -np.inf)
        self.reached = np.zeros(4, dtype=bool)

    def _draw(self, first_index: int, count: int) -> list[Task]:
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, len(self.space))
        unit = 0.5 + (uniforms - 0.5) * self.params.spread
        return [self.space.from_array(row) for row in self.space.from_unit(unit)]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        self.best = result.reward if self.best is None else max(self.best, result.reward)
        quarter = min(int(4 * self.space.to_unit(self.space.to_array(result.task))[0]), 3)
        self.results[quarter] += 1
        self.bests[quarter] = max(self.bests[quarter], result.reward)
        self.reached[quarter] |= result.reward >= 10.0
        return None

    def _describe(self) -> dict[str, Any]:
        return {
            "best": self.best,
            "results": self.results.tolist(),
            "bests": [None if np.isinf(b) else float(b) for b in self.bests],
            "reached": self.reached.tolist(),
        }
'''


def add_toy_kind(tree: Path) -> None:
    (tree / TOY_MODULE).write_text(TOY_SOURCE)
    registry = tree / REGISTRY
    text = registry.read_text()
    anchor = "from teacher_service.teachers.uniform import"
    assert text.count(anchor) == 1 and text.count("            LearnabilityTeacher,\n") == 1
    text = text.replace(anchor, "from teacher_service.teachers.toy import ToyTeacher\n" + anchor)
    text = text.replace(
        "            LearnabilityTeacher,\n", "            LearnabilityTeacher,\n            ToyTeacher,\n"
    )
    registry.write_text(text)


@pytest.fixture(scope="module")
def trees(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    before, after = tmp_path_factory.mktemp("before"), tmp_path_factory.mktemp("after")
    return copies_before_and_after(before, after, PACKAGES, add_toy_kind)


def test_a_new_kind_is_its_module_and_the_registry(trees: tuple[Path, Path]) -> None:
    before, after = trees
    assert changed_files(before, after) == sorted([str(REGISTRY), str(TOY_MODULE)])
    added = [line for line in (after / REGISTRY).read_text().splitlines() if "Toy" in line]
    assert added == ["from teacher_service.teachers.toy import ToyTeacher", "            ToyTeacher,"]


@pytest.fixture(scope="module")
def toy_service(trees: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServiceProcess]:
    """The copy with the toy kind served: its packages first on the path, the checkout's kept out."""
    _, after = trees
    env = {"PYTHONPATH": str(after), "PYTHONSAFEPATH": "1"}
    with ServiceProcess(tmp_path_factory.mktemp("toy") / "teacher.db", env=env) as service:
        yield service


SPACE = [{"name": "x", "low": 0.0, "high": 10.0}, {"name": "y", "low": -1.0, "high": 1.0}]


def test_the_new_kind_is_served_checked_taught_and_restored(toy_service: ServiceProcess) -> None:
    with httpx.Client(base_url=f"{toy_service.url}/api/v1", timeout=30.0) as http:
        kinds = {entry["kind"]: entry for entry in http.get("/teachers").json()["teachers"]}
        [spread] = kinds["toy"]["parameters"]
        assert (spread["name"], spread["minimum"], spread["maximum"], spread["default"]) == ("spread", 0.0, 1.0, 0.5)

        refused = http.put("/curricula/bad", json={"teacher": "toy", "space": SPACE, "params": {"spread": 2}})
        assert refused.status_code == 422 and "spread" in refused.text

        created = http.put("/curricula/toy", json={"teacher": "toy", "space": SPACE, "params": {"spread": 0.2}})
        assert created.status_code == 201, created.text
        tasks = http.post("/curricula/toy/tasks", json={"count": 20}).json()["tasks"]
        assert all(4.0 <= task["params"]["x"] <= 6.0 and -0.2 <= task["params"]["y"] <= 0.2 for task in tasks)
        results = [{"task_id": task["task_id"], "reward": float(i)} for i, task in enumerate(tasks)]
        assert http.post("/curricula/toy/results", json={"results": results}).json()["accepted"] == 20
        before = http.get("/curricula/toy/state").json()["teacher"]
        assert before["best"] == 19.0 and before["results_seen"] == 20
        assert sum(before["results"]) == 20 and before["results"][0] == before["results"][3] == 0
        assert before["reached"][1] or before["reached"][2]

    toy_service.stop()
    toy_service.start()
    with httpx.Client(base_url=f"{toy_service.url}/api/v1", timeout=30.0) as http:
        after = http.get("/curricula/toy/state").json()["teacher"]
        assert after == before, "the restarted service restored the toy kind as it was"
