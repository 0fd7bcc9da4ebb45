"""A target given as a box (``target="box"``, ``target_box``) for CURROT and self-paced: refused when
inconsistent or outside the space, heading for the box while leaving its free parameters spread,
set from the command line's JSON, and kept through a snapshot."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from common.client.schemas import CurriculumSpec, ParameterSpec
from common.client.task_space import Parameter, TaskSpace
from common.kuka.task_space import KUKA_HARD_V1_TASK_SPACE
from learner.commands.arguments import setting
from teacher_service.curriculum_spec import stored_spec
from teacher_service.teachers import EpisodeResult, Teacher, make_teacher
from teacher_service.teachers.algorithms.currot import TargetBox
from teacher_service.teachers.params import box_in_space

SPACE = TaskSpace(
    [
        Parameter("a", 0.0, 1.0, hardest=1.0, easiest=0.0),
        Parameter("free", 0.0, 2.0, hardest=0.0, easiest=2.0),
    ]
)
"""``free`` plays KUKA's ``shaping``: hardest at its low end, and left free by the box below."""

FREE = {"free": [0.0, 2.0]}
CURROT = {"particles": 50, "update_every": 25, "candidates": 16}
SELF_PACED = {"update_every": 50, "kl_limit": 0.1}
KINDS = [("currot", CURROT), ("self-paced", SELF_PACED)]


def teacher(kind: str, params: dict[str, Any], space: TaskSpace = SPACE, seed: int = 0) -> Teacher:
    defaults = CURROT if kind == "currot" else SELF_PACED
    return make_teacher(kind, space, seed, {**defaults, **params})


def succeed_everywhere(taught: Teacher, results: int) -> None:
    for _ in range(results):
        task = taught.sample(1)[0]
        taught.learn_and_fit(EpisodeResult(task, 10.0, success=True))


@pytest.mark.parametrize(("kind", "_"), KINDS)
@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"target": "box"}, "target 'box' needs a target_box: parameter name to \\[low, high\\]"),
        ({"target": "box", "target_box": {}}, r"target_box\n  Dictionary should have at least 1 item"),
        ({"target": "uniform", "target_box": FREE}, "target_box is read only with target 'box', not 'uniform'"),
        ({"target": "hardest", "target_box": FREE}, "target_box is read only with target 'box', not 'hardest'"),
        (
            {"target": "box", "target_box": {"shaping": [0, 1]}},
            r"target_box: unknown task parameter\(s\) \['shaping'\]; expected \['a', 'free'\]",
        ),
        (
            {"target": "box", "target_box": {"a": [0.8, 0.2]}},
            r"target_box: 'a' needs low <= high, got \[0.8, 0.2\]",
        ),
        (
            {"target": "box", "target_box": {"free": [0.0, 2.5]}},
            r"target_box: 'free' range \[0.0, 2.5\] is outside its bounds \[0.0, 2.0\]",
        ),
        ({"target": "box", "target_box": {"a": [0, 0.5, 1]}}, r"target_box.a\n  List should have at most 2 items"),
        ({"target": "box", "target_box": {"a": ["0", 1]}}, r"target_box.a.0\n  Input should be a valid number"),
        ({"target": "box", "target_box": {"a": [0, math.inf]}}, r"target_box.a.1\n  Input should be a finite number"),
        (
            {"target": "box", "target_box": {f"p{i}": [0, 1] for i in range(65)}},
            r"target_box\n  Dictionary should have at most 64 items",
        ),
    ],
)
def test_an_inconsistent_or_outside_box_is_refused_by_name(
    kind: str, _: dict[str, Any], params: dict[str, Any], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        teacher(kind, params)


@pytest.mark.parametrize(("kind", "_"), KINDS)
def test_a_parameter_left_out_needs_a_hardest_value(kind: str, _: dict[str, Any]) -> None:
    unanchored = TaskSpace([Parameter("a", 0.0, 1.0, easiest=0.0), Parameter("b", 0.0, 1.0, easiest=0.0)])
    with pytest.raises(ValueError, match="target_box: 'b' is not given and this task space defines no hardest value"):
        teacher(kind, {"target": "box", "target_box": {"a": [0, 1]}}, unanchored)
    teacher(kind, {"target": "box", "target_box": {"a": [0, 1], "b": [0.5, 0.5]}}, unanchored)


def test_the_box_in_unit_coordinates_holds_what_it_does_not_name_at_the_hardest_value() -> None:
    low, high = box_in_space("target_box", {"free": [0.5, 1.5]}, SPACE)
    assert low.tolist() == [1.0, 0.25] and high.tolist() == [1.0, 0.75]


def test_currot_target_samples_are_uniform_in_the_box_and_its_state_shows_the_box() -> None:
    low, high = box_in_space("target_box", {"free": [0.5, 1.5]}, SPACE)
    samples = TargetBox(low, high).samples(np.random.default_rng(0).random, 2000)
    assert np.all(samples[:, 0] == 1.0)
    assert samples[:, 1].min() >= 0.25 and samples[:, 1].max() <= 0.75
    assert np.std(samples[:, 1]) == pytest.approx(0.5 / math.sqrt(12), rel=0.05)
    state = teacher("currot", {"target": "box", "target_box": {"free": [0.5, 1.5]}}).state()
    assert state["target"] == {"a": [1.0, 1.0], "free": [0.5, 1.5]}
    assert state["params"]["target_box"] == {"free": [0.5, 1.5]}


def test_currot_heads_for_the_box_leaving_the_free_parameter_spread() -> None:
    """Every task succeeds, so every particle may go where its target sample is: with the box they
    reach the hardest ``a`` and stay spread over ``free``; with the hardest point ``free`` collapses."""
    boxed = teacher("currot", {"target": "box", "target_box": FREE})
    hardest = teacher("currot", {"target": "hardest"})
    for taught in (boxed, hardest):
        succeed_everywhere(taught, 1500)
    box_particles = np.array([[task["a"], task["free"]] for task in boxed.state()["particles"]])
    point_particles = np.array([[task["a"], task["free"]] for task in hardest.state()["particles"]])
    assert box_particles[:, 0].min() > 0.9 and point_particles[:, 0].min() > 0.9
    assert np.std(box_particles[:, 1]) > 0.4, "a uniform spread over [0, 2] has a standard deviation of 0.58"
    assert box_particles[:, 1].min() < 0.3 and box_particles[:, 1].max() > 1.7
    assert point_particles[:, 1].max() < 0.1


def test_self_paced_stands_in_for_the_box_with_the_uniforms_spread_and_target_spread_for_a_point() -> None:
    component = teacher("self-paced", {"target": "box", "target_box": {"free": [0.5, 1.5]}}).state()["target"]
    assert component["mean"] == {"a": 1.0, "free": 1.0}
    assert np.sqrt(np.diag(component["covariance"])) == pytest.approx([0.05, 1.0 / math.sqrt(12)])
    points = {"target": "box", "target_box": {"a": [1, 1], "free": [0, 0]}}
    assert teacher("self-paced", points).state()["target"] == teacher("self-paced", {}).state()["target"]
    everything = {"target": "box", "target_box": {"a": [0, 1], "free": [0, 2]}}
    assert (
        teacher("self-paced", everything).state()["target"]
        == teacher("self-paced", {"target": "uniform"}).state()["target"]
    )


def test_self_paced_heads_for_the_box_leaving_the_free_parameter_spread() -> None:
    boxed = teacher("self-paced", {"target": "box", "target_box": FREE})
    succeed_everywhere(boxed, 2500)
    gaussian = boxed.state()["components"][0]
    assert gaussian["mean"]["a"] == pytest.approx(1.0, abs=0.02)
    assert gaussian["mean"]["free"] == pytest.approx(1.0, abs=0.1)
    spreads = np.sqrt(np.diag(gaussian["covariance"]))
    assert spreads[0] < 0.1, "held near the hardest a"
    assert spreads[1] > 0.45, "spread over free as the uniform over [0, 2] (0.58)"


@pytest.mark.parametrize(("kind", "_"), KINDS)
def test_a_box_target_survives_a_snapshot_with_its_params_read_back_from_json(kind: str, _: dict[str, Any]) -> None:
    params = {"target": "box", "target_box": {"free": [0.25, 1.75]}}
    original = teacher(kind, params)
    succeed_everywhere(original, 260)
    stored = json.loads(json.dumps(original.snapshot(), allow_nan=False))
    restored = teacher(kind, json.loads(json.dumps(original.state()["params"])))
    restored.restore(stored, original.history(original.history_kept_from(stored)))
    assert restored.state() == original.state()
    succeed_everywhere(original, 140)
    succeed_everywhere(restored, 140)
    assert restored.state() == original.state()
    assert restored.sample(20) == original.sample(20)


@pytest.mark.parametrize("kind", ["currot", "self-paced"])
def test_the_command_lines_json_value_reaches_the_teacher(kind: str) -> None:
    """``--teacher-param 'target_box={"shaping": [0, 1]}'``: parsed as JSON, sent in a curriculum
    spec, read back as the service reads it, and held by the teacher on KukaGraspHard-v1."""
    params = dict([setting("target=box"), setting('target_box={"shaping": [0, 1]}')])
    assert params == {"target": "box", "target_box": {"shaping": [0, 1]}}
    space = [ParameterSpec.from_parameter(p) for p in KUKA_HARD_V1_TASK_SPACE.parameters]
    spec = stored_spec(CurriculumSpec(teacher=kind, space=space, params=params).model_dump_json())
    taught = make_teacher(kind, spec.task_space(), 0, spec.params)
    hardest = KUKA_HARD_V1_TASK_SPACE.hardest()
    if kind == "currot":
        target = taught.state()["target"]
        assert target["shaping"] == [0.0, 1.0]
        assert all(
            target[name] == pytest.approx([value, value]) for name, value in hardest.items() if name != "shaping"
        )
    else:
        mean = taught.state()["target"]["mean"]
        assert mean["shaping"] == 0.5
        assert all(mean[name] == pytest.approx(value) for name, value in hardest.items() if name != "shaping")
