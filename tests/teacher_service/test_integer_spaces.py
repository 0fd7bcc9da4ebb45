"""Integer parameters through a real service: the kinds that can teach them hand out ints, the others
refuse the space with a 422 naming the parameter, and every bad integer space is refused before
anything is stored."""

from __future__ import annotations

from collections import Counter

import httpx
import pytest

from common.client.task_space import Parameter, TaskSpace
from teacher_service.teachers import make_teacher

LEVELS = [{"name": "level", "type": "integer", "low": 0, "high": 199}]
MIXED = [{"name": "level", "type": "integer", "low": 3, "high": 5}, {"name": "friction", "low": 0.5, "high": 1.5}]


def test_the_catalogue_says_which_parameter_types_each_kind_takes(http: httpx.Client) -> None:
    kinds = {entry["kind"]: entry["parameter_types"] for entry in http.get("/teachers").json()["teachers"]}
    assert kinds["random"] == kinds["fixed"] == kinds["manual"] == ["float", "integer"]
    assert kinds["alp-gmm"] == kinds["currot"] == ["float"]


def test_random_over_levels_hands_out_ints_inside_the_bounds(http: httpx.Client) -> None:
    created = http.put("/curricula/levels-random", json={"teacher": "random", "space": LEVELS, "seed": 1})
    assert created.status_code == 201, created.text
    assert created.json()["config"]["space"][0]["type"] == "integer"
    response = http.post("/curricula/levels-random/tasks", json={"count": 200})
    levels = [task["params"]["level"] for task in response.json()["tasks"]]
    assert all(isinstance(level, int) and 0 <= level <= 199 for level in levels)
    assert '"level":' in response.text and ".0" not in response.text.split('"level":')[1][:6], "ints on the wire"
    results = [{"task_id": task["task_id"], "reward": 1.0} for task in response.json()["tasks"]]
    assert http.post("/curricula/levels-random/results", json={"results": results}).json()["accepted"] == 200


def test_a_mixed_space_keeps_each_parameter_in_its_type(http: httpx.Client) -> None:
    assert http.put("/curricula/mixed", json={"teacher": "random", "space": MIXED}).status_code == 201
    tasks = http.post("/curricula/mixed/tasks", json={"count": 50}).json()["tasks"]
    assert all(isinstance(task["params"]["level"], int) for task in tasks)
    assert all(isinstance(task["params"]["friction"], float) for task in tasks)


@pytest.mark.parametrize(
    ("teacher", "space", "message"),
    [
        ("alp-gmm", LEVELS, "parameter 'level' is an integer parameter: the alp-gmm teacher takes float"),
        ("currot", MIXED, "parameter 'level' is an integer parameter: the currot teacher takes float"),
        ("random", [{"name": "level", "type": "integer", "low": 0.5, "high": 9}], "low=0.5 is not whole"),
        ("random", [{"name": "level", "type": "integr", "low": 0, "high": 9}], "type"),
    ],
)
def test_a_space_a_kind_cannot_teach_is_a_422_naming_the_parameter(
    http: httpx.Client, teacher: str, space: list[dict[str, object]], message: str
) -> None:
    response = http.put("/curricula/refused", json={"teacher": teacher, "space": space})
    assert response.status_code == 422 and message in response.text, response.text
    assert http.get("/curricula/refused").status_code == 404, "nothing was stored"


def test_random_gives_every_level_an_equal_share_ends_included() -> None:
    teacher = make_teacher("random", TaskSpace([Parameter("level", 0, 3, type="integer")]), seed=0)
    counts = Counter(task["level"] for task in teacher.sample(8000))
    assert sorted(counts) == [0, 1, 2, 3]
    assert all(1800 <= count <= 2200 for count in counts.values()), counts
