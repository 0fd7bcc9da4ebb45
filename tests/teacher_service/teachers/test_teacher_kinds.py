"""Behaviour every teacher kind shares: the factory, bounds, determinism, replay and JSON state."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from scripted_student import run_student

from common.client.task_space import Parameter, TaskSpace
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.teachers import TEACHER_KINDS, EpisodeResult, Teacher, make_teacher

# Small fits keep the suite fast; the defaults are exercised in test_alp_gmm_teacher.py.
KIND_PARAMS: dict[str, dict[str, Any]] = {
    "alp-gmm": {"fit_rate": 40, "max_components": 4, "reward_range": [-2.0, 2.0]},
    "manual": {"threshold": 0.5, "window": 5, "min_episodes": 5},
    "random": {},
    "fixed": {},
    "adr": {"queue_length": 3, "reward_range": [-1.0, 1.0]},
    "self-paced": {"update_every": 20, "reward_range": [-1.0, 1.0]},
    "currot": {"particles": 40, "update_every": 20, "buffer_size": 60, "candidates": 8, "delta": 0.0},
    "covar-gmm": {"fit_rate": 40, "max_components": 4},
    "riac": {"max_region_size": 30},
    "learnability": {"pool_size": 40, "update_every": 20, "buffer_size": 60, "top_k": 10},
    "plr": {"robust": True},
    "learning-progress": {"update_every": 10},
}
LEVELS = TaskSpace(
    [Parameter("seed", 0, 199, type="integer", hardest=199), Parameter("layout", 1, 3, type="integer", hardest=3)]
)
"""A MultiDiscrete space of 600 levels, for the kinds that teach levels only."""


def space_of(kind: str) -> TaskSpace:
    """KUKA's box for the kinds that teach floats; a level space for those that teach integers only."""
    return KUKA_TASK_SPACE if "float" in TEACHER_KINDS[kind].parameter_types else LEVELS


def build(kind: str, seed: int = 3) -> Teacher:
    return make_teacher(kind, space_of(kind), seed, KIND_PARAMS[kind])


def assert_in_bounds(space: TaskSpace, tasks: list[dict[str, float]]) -> None:
    for task in tasks:
        assert space.validate(task) == task


def assert_plain_json(value: Any) -> None:
    """Only the types ``json.loads`` produces, so the state survives any encoder unchanged."""
    if isinstance(value, dict):
        assert all(type(key) is str for key in value)
        for item in value.values():
            assert_plain_json(item)
    elif isinstance(value, list):
        for item in value:
            assert_plain_json(item)
    else:
        assert type(value) in (str, int, float, bool, type(None)), f"{value!r} is a {type(value).__name__}"


def test_every_kind_is_registered() -> None:
    assert set(TEACHER_KINDS) == set(KIND_PARAMS)
    for kind in KIND_PARAMS:
        assert build(kind).kind == kind


@pytest.mark.parametrize("kind", sorted(KIND_PARAMS))
def test_tasks_stay_inside_the_box(kind: str) -> None:
    teacher = build(kind)
    handed_out = run_student(teacher, 200, batch=7)
    assert_in_bounds(space_of(kind), handed_out + teacher.sample(2000))


@pytest.mark.parametrize("kind", sorted(KIND_PARAMS))
def test_same_seed_and_results_give_the_same_tasks(kind: str) -> None:
    first, second = build(kind), build(kind)
    assert run_student(first, 120, batch=5) == run_student(second, 120, batch=5)
    assert first.sample(50) == second.sample(50)
    assert first.state() == second.state()


@pytest.mark.parametrize("kind", sorted(KIND_PARAMS))
def test_batching_does_not_change_the_tasks(kind: str) -> None:
    at_once, in_pieces = build(kind), build(kind)
    run_student(at_once, 100)
    run_student(in_pieces, 100)
    assert at_once.sample(30) == in_pieces.sample(1) + in_pieces.sample(12) + in_pieces.sample(17)


@pytest.mark.parametrize("kind", ["alp-gmm", "random", "adr", "self-paced"])
def test_the_seed_matters(kind: str) -> None:
    assert run_student(build(kind, seed=3), 100) != run_student(build(kind, seed=4), 100)


@pytest.mark.parametrize("kind", sorted(KIND_PARAMS))
def test_replaying_the_history_rebuilds_the_teacher(kind: str) -> None:
    live = build(kind)
    history: list[tuple[int, EpisodeResult]] = []
    for step in range(90):
        tasks = live.sample(1 + step % 3)
        result = EpisodeResult(tasks[0], reward=float(step % 7) / 3 - 1)
        live.learn_and_fit(result)
        history.append((len(tasks), result))
    live.sample(4)

    rebuilt = build(kind)
    for handed_out, result in history:
        rebuilt.skip(handed_out)
        rebuilt.learn_and_fit(result)
    rebuilt.skip(4)

    assert rebuilt.state() == live.state()
    assert rebuilt.sample(30) == live.sample(30)


def restored_copy(teacher: Teacher) -> Teacher:
    """A fresh teacher restored from ``teacher``'s snapshot, the snapshot passed through JSON text and
    the history rows it needs split in two chunks, as a store keeps them."""
    snapshot = json.loads(json.dumps(teacher.snapshot(), allow_nan=False))
    kept_from = Teacher.history_kept_from(snapshot)
    half = (kept_from + teacher.history_size) // 2
    history = teacher.history(kept_from)
    chunks = np.concatenate([history[: half - kept_from], teacher.history(half)]) if teacher.history_size else history
    restored = build(teacher.kind)
    restored.restore(snapshot, chunks)
    return restored


@pytest.mark.parametrize("kind", sorted(KIND_PARAMS))
def test_a_restored_teacher_is_the_same_teacher(kind: str) -> None:
    original = build(kind)
    run_student(original, 130, batch=7)
    original.sample(5)  # handed out, no result yet
    learned = {
        "alp-gmm": ("fits", 3),
        "manual": ("lesson", 1),
        "adr": ("widened", 3),
        "self-paced": ("updates", 3),
        "currot": ("fits", 3),
        "covar-gmm": ("fits", 3),
        "riac": ("splits", 2),
        "learnability": ("refreshes", 3),
        "plr": ("scored_levels", 50),
        "learning-progress": ("updates", 10),
    }
    if kind in learned:
        entry, least = learned[kind]
        assert original.state()[entry] >= least, "the snapshot must hold learned state, not just counters"

    restored = restored_copy(original)
    assert restored.state() == original.state()
    assert run_student(restored, 150, batch=4) == run_student(original, 150, batch=4)
    assert restored.sample(40) == original.sample(40)
    assert restored.state() == original.state()


@pytest.mark.parametrize("kind", sorted(KIND_PARAMS))
def test_a_snapshot_restores_only_a_fresh_teacher_of_its_kind(kind: str) -> None:
    teacher = build(kind)
    run_student(teacher, 10)
    used = build(kind)
    used.sample(1)
    with pytest.raises(RuntimeError, match="fresh teacher"):
        used.restore(teacher.snapshot(), teacher.history(0))
    other = build("fixed" if kind != "fixed" else "random")
    with pytest.raises(ValueError, match=f"a {kind} snapshot cannot restore"):
        other.restore(teacher.snapshot(), teacher.history(0))


@pytest.mark.parametrize("kind", sorted(KIND_PARAMS))
def test_state_is_plain_json(kind: str) -> None:
    teacher = build(kind)
    run_student(teacher, 100)
    state = teacher.state()
    assert_plain_json(state)
    assert json.loads(json.dumps(state)) == state
    assert state["kind"] == kind
    assert state["tasks_sampled"] == 100 and state["results_seen"] == 100


def test_unknown_kind_is_rejected_by_name() -> None:
    with pytest.raises(ValueError, match="unknown teacher kind 'alpgmm'"):
        make_teacher("alpgmm", KUKA_TASK_SPACE, 0)


@pytest.mark.parametrize(
    ("kind", "params", "message"),
    [
        ("alp-gmm", {"fitrate": 10}, r"fitrate\n  Extra inputs are not permitted"),
        ("alp-gmm", {"fit_rate": 1}, r"fit_rate\n  Input should be greater than or equal to 2"),
        ("alp-gmm", {"fit_rate": 2001}, r"fit_rate\n  Input should be less than or equal to 2000"),
        ("alp-gmm", {"fit_rate": 20.5}, r"fit_rate\n  Input should be a valid integer"),
        ("alp-gmm", {"random_task_ratio": 1.5}, r"random_task_ratio\n  Input should be less than or equal to 1"),
        ("alp-gmm", {"max_components": 300}, r"max_components\n  Input should be less than or equal to 16"),
        ("alp-gmm", {"fit_rate": 10, "max_components": 12}, r"max_components \(12\) cannot exceed fit_rate"),
        ("alp-gmm", {"min_components": 5, "max_components": 4}, "min_components"),
        ("alp-gmm", {"nb_em_init": 6}, r"nb_em_init\n  Input should be less than or equal to 5"),
        ("alp-gmm", {"buffer_size": 10**12}, r"buffer_size\n  Input should be less than or equal to 10000"),
        ("alp-gmm", {"rescale_tasks": "yes"}, r"rescale_tasks\n  Input should be a valid boolean"),
        ("alp-gmm", {"reward_range": [1.0, 1.0]}, "reward_range must have low < high"),
        ("alp-gmm", {"reward_range": [0.0, "ten"]}, r"reward_range.1\n  Input should be a valid number"),
        ("alp-gmm", {"reward_range": [0.0, 1.0, 2.0]}, r"reward_range\n  List should have at most 2 items"),
        ("alp-gmm", {"nb_em_init": True}, r"nb_em_init\n  Input should be a valid integer"),
        ("alp-gmm", {"bootstrap_spread": -0.1}, r"bootstrap_spread\n  Input should be greater than or equal to 0"),
        ("alp-gmm", {"bootstrap_spread": "narrow"}, r"bootstrap_spread\n  Input should be a valid number"),
        ("covar-gmm", {"fit_rate": 3}, r"fit_rate\n  Input should be greater than or equal to 4"),
        ("covar-gmm", {"fit_rate": 10, "max_components": 12}, r"max_components \(12\) cannot exceed fit_rate"),
        ("covar-gmm", {"min_components": 5, "max_components": 4}, r"min_components \(5\) cannot exceed max_comp"),
        ("manual", {"threshold": float("nan")}, r"threshold\n  Input should be a finite number"),
        ("manual", {"window": 10, "min_episodes": 20}, r"min_episodes \(20\) cannot exceed window"),
        ("manual", {"window": 10**9}, r"window\n  Input should be less than or equal to 10000"),
        ("manual", {"start": {"jp2": 0.5}}, "start: missing task parameter"),
        ("manual", {"start": {**KUKA_TASK_SPACE.easiest(), "jp2": 2.0}}, "start: task parameter 'jp2'"),
        ("random", {"seed": 1}, r"seed\n  Extra inputs are not permitted"),
        ("fixed", {"point": {**KUKA_TASK_SPACE.hardest(), "bias_obj_y": 0.5}}, "point: task parameter 'bias_obj_y'"),
        ("fixed", {"point": "hardest"}, r"point\n  Input should be a valid dictionary"),
        ("fixed", [("point", None)], "parameters must be a mapping of name to value, got list"),
    ],
)
def test_bad_parameters_are_rejected_by_name(kind: str, params: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make_teacher(kind, KUKA_TASK_SPACE, 0, params)


@pytest.mark.parametrize("seed", [-1, 1.5, True, "7"])
def test_bad_seeds_are_rejected(seed: Any) -> None:
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        make_teacher("random", KUKA_TASK_SPACE, seed)


@pytest.mark.parametrize("kind", sorted(KIND_PARAMS))
def test_bad_input_is_rejected_without_changing_the_teacher(kind: str) -> None:
    teacher = build(kind)
    space = space_of(kind)
    name = space.names[0]
    outside = {**space.hardest(), name: space.parameters[0].high + 1}
    with pytest.raises(ValueError, match=name):
        teacher.learn(EpisodeResult(outside, 1.0))
    with pytest.raises(ValueError, match="count must be a non-negative integer"):
        teacher.sample(-1)
    with pytest.raises(ValueError, match="reward must be finite"):
        EpisodeResult(space.hardest(), float("inf"))
    with pytest.raises(ValueError, match="score must be finite"):
        EpisodeResult(space.hardest(), 1.0, score=float("nan"))
    assert teacher.results_seen == 0 and teacher.tasks_drawn == 0


def test_fixed_teacher_defaults_to_the_hardest_point_and_needs_one() -> None:
    assert build("fixed").sample(3) == [KUKA_TASK_SPACE.hardest()] * 3
    point = {**KUKA_TASK_SPACE.easiest(), "rnd_obj_x": 0.5}
    assert make_teacher("fixed", KUKA_TASK_SPACE, 0, {"point": point}).sample(1) == [point]
    unanchored = TaskSpace([Parameter("x", 0.0, 1.0)])
    with pytest.raises(ValueError, match="point: none given"):
        make_teacher("fixed", unanchored, 0)


def test_random_teacher_covers_the_box_evenly() -> None:
    tasks = make_teacher("random", KUKA_TASK_SPACE, 0).sample(4000)
    for parameter in KUKA_TASK_SPACE.parameters:
        values = sorted(task[parameter.name] for task in tasks)
        width = parameter.high - parameter.low
        quartiles = [values[len(values) * q // 4] for q in (1, 2, 3)]
        expected = [parameter.low + width * q / 4 for q in (1, 2, 3)]
        assert quartiles == pytest.approx(expected, abs=0.05 * width)
