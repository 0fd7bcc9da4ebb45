"""SPDL: the Gaussian moves toward the target within the KL limit while the expected performance
stays above the bar, turns toward what the student manages when it does not, and stays put when
nothing is managed."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest
from reach_student import SQUARE, ReachStudent, practise
from scipy.special import ndtri

from common.client.task_space import Parameter, TaskSpace
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.teachers import EpisodeResult, Teacher, make_teacher
from teacher_service.teachers.self_paced import Gaussian, _pull_back, update_gaussian

KL_LIMIT = 0.1


def spdl(**params: Any) -> Teacher:
    return make_teacher("self-paced", SQUARE, 1, {"update_every": 50, "kl_limit": KL_LIMIT, **params})


def mean_of(teacher: Teacher) -> dict[str, float]:
    mean: dict[str, float] = teacher.state()["components"][0]["mean"]
    return mean


def spread_of(teacher: Teacher) -> list[float]:
    covariance = teacher.state()["components"][0]["covariance"]
    return [math.sqrt(covariance[d][d]) for d in range(len(covariance))]


def test_starts_narrow_on_the_easiest_task_and_draws_it_truncated_to_the_box() -> None:
    teacher = spdl()
    assert mean_of(teacher) == SQUARE.easiest()
    assert spread_of(teacher) == pytest.approx([0.05, 0.2])
    tasks = teacher.sample(2000)
    xs = np.array([task["x"] for task in tasks])
    assert xs.min() > 0.0, "truncated, not clipped: no draw piles up on the box's face"
    assert np.median(xs) == pytest.approx(0.6745 * 0.05, abs=0.004), "the half-normal's median"
    assert np.mean(xs < 0.05) == pytest.approx(0.683, abs=0.03), "one standard deviation holds 68%"


def test_moves_to_the_hardest_task_while_the_student_keeps_up() -> None:
    teacher = spdl()
    student = ReachStudent(0.1, growth=0.002)
    for _ in range(60):
        practise(teacher, student, 50)
    state = teacher.state()
    assert state["updates"] == 60
    assert mean_of(teacher) == pytest.approx(SQUARE.hardest(), abs=1e-6)
    assert state["kl_to_target"] == pytest.approx(0.0, abs=1e-6)
    toward = [move for move in state["moves"] if move["why"] == "toward the target"]
    assert len(toward) >= 10
    for move in toward:
        assert 0.0 < move["kl"] <= KL_LIMIT * (1 + 1e-6)
        assert move["expected_performance_after"] >= 0.25
    distances = [move["kl_to_target"] for move in toward]
    assert distances == sorted(distances, reverse=True) and len(set(distances)) == len(distances)


def test_climbing_holds_a_stuck_student_near_the_bar_and_never_steps_toward_the_target_below_it() -> None:
    teacher = spdl(below_bar="climb")
    student = ReachStudent(0.3)
    successes = []
    for _ in range(2000):
        task = teacher.sample(1)[0]
        successes.append(student.attempt(task))
        teacher.learn_and_fit(EpisodeResult(task, reward=0.0, success=successes[-1]))
    state = teacher.state()
    assert state["kl_to_target"] > 100, "far from the target (a student that keeps up arrives: see above)"
    assert np.mean(successes[-1000:]) >= 0.2, "the student keeps succeeding about as often as the bar asks"
    moves = state["moves"]
    toward = [move for move in moves if move["why"] == "toward the target"]
    assert all(move["expected_performance_after"] >= 0.25 for move in toward), "the bar holds every step"
    below = [i for i, move in enumerate(moves) if move["why"] == "below the bar: toward better performance"]
    assert len(below) >= 3, "the Gaussian reaches past the student's reach and comes back"
    for i in below:
        assert moves[i]["expected_performance"] < 0.25
        assert moves[i]["expected_performance_after"] > moves[i]["expected_performance"]
        assert moves[i]["kl"] <= KL_LIMIT * (1 + 1e-6)
        assert moves[i]["kl_to_target"] > moves[i - 1]["kl_to_target"], "below the bar it steps away"


def test_by_default_a_stuck_student_keeps_the_gaussian_where_it_was_and_it_never_steps_back() -> None:
    teacher = spdl()
    student = ReachStudent(0.3)
    for _ in range(2000):
        task = teacher.sample(1)[0]
        teacher.learn_and_fit(EpisodeResult(task, reward=0.0, success=student.attempt(task)))
    state = teacher.state()
    assert state["bar_reached"] and state["kl_to_target"] > 100
    moves = state["moves"]
    first = next(i for i, move in enumerate(moves) if move["expected_performance"] >= 0.25)
    assert all(move["why"].startswith("below the bar: toward better") for move in moves[:first])
    later = moves[first:]
    assert {move["why"] for move in later if move["expected_performance"] < 0.25} <= {
        "below the bar: toward the target",
        "below the bar: no step toward the target keeps the bar",
    }
    assert any(move["why"] == "below the bar: no step toward the target keeps the bar" for move in later)
    distances = [move["kl_to_target"] for move in later]
    assert distances == sorted(distances, reverse=True), "once the bar was reached it never steps away"
    assert all(move["expected_performance_after"] >= 0.25 for move in later if move["kl"] > 0)


def test_the_bar_limits_a_step_that_the_kl_limit_would_allow() -> None:
    old = Gaussian(np.array([0.25]), np.log(np.array([0.1])))
    target = Gaussian(np.array([1.0]), np.log(np.array([0.05])))
    points = np.clip(old.mean + 0.1 * ndtri((np.arange(200) + 0.5) / 200), 0.0, 1.0)[:, np.newaxis]
    scores = (points[:, 0] <= 0.3).astype(float)
    free = update_gaussian(old, target, points, scores, bar=0.0, kl_limit=0.5)
    assert free.kl_step == pytest.approx(0.5, rel=1e-3), "with no bar the KL limit binds"
    barred = update_gaussian(old, target, points, scores, bar=0.55, kl_limit=0.5)
    assert barred.why == "toward the target" and barred.expected_before > 0.55
    assert barred.expected_after == pytest.approx(0.55, abs=1e-3), "the bar binds"
    assert old.mean[0] < barred.gaussian.mean[0] < free.gaussian.mean[0]


def test_an_optimiser_step_outside_the_constraints_is_pulled_back_or_dropped() -> None:
    assert _pull_back(np.array([0.5, -0.5]), lambda x: True).tolist() == [0.5, -0.5]
    assert _pull_back(np.array([2.0, 4.0]), lambda x: x[0] <= 1.0) == pytest.approx([1.0, 2.0], abs=1e-6)
    assert _pull_back(np.array([np.nan, 1.0]), lambda x: True).tolist() == [0.0, 0.0]
    assert _pull_back(np.array([1.0, 1.0]), lambda x: False).tolist() == [0.0, 0.0]


def test_stays_put_when_the_student_fails_everywhere() -> None:
    teacher = spdl()
    before = teacher.state()["components"]
    practise(teacher, ReachStudent(-1.0), 200)
    state = teacher.state()
    assert state["updates"] == 4 and state["components"] == before
    assert {move["why"] for move in state["moves"]} == {"below the bar, and no better performance within reach"}
    assert all(move["kl"] == 0.0 and move["from"] == move["to"] for move in state["moves"])


def test_moves_toward_the_uniform_target() -> None:
    teacher = spdl(target="uniform", kl_limit=0.5)
    start = teacher.state()["kl_to_target"]
    practise(teacher, ReachStudent(1.0), 2000)
    assert teacher.state()["kl_to_target"] < start / 100
    assert mean_of(teacher) == pytest.approx({"x": 0.5, "y": 0.0}, abs=0.05)
    assert spread_of(teacher) == pytest.approx([1 / math.sqrt(12), 4 / math.sqrt(12)], rel=0.1)


def test_the_bar_is_on_the_scaled_return_without_success() -> None:
    below, above = spdl(reward_range=[0.0, 10.0]), spdl(reward_range=[0.0, 10.0])
    for teacher, reward in ((below, 2.0), (above, 3.0)):
        for _ in range(50):
            teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], reward=reward))
    assert below.state()["moves"][0]["why"].startswith("below the bar")
    assert above.state()["moves"][0]["why"] == "toward the target"


def test_without_a_reward_range_the_bar_is_on_returns_placed_between_the_lowest_and_highest_seen() -> None:
    below, above = spdl(), spdl()
    for teacher, best in ((below, 5), (above, 15)):
        for index in range(50):
            teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], reward=-20.0 if index >= best else 40.0))
    assert below.state()["moves"][0]["why"].startswith("below the bar"), "5 of 50 at the best return: 0.1"
    assert above.state()["moves"][0]["why"] == "toward the target", "15 of 50: 0.3"
    assert above.state()["reward_scale"] == {"source": "learned from the returns seen", "range": [-20.0, 40.0]}


def test_a_restored_teacher_continues_the_same_run() -> None:
    original = spdl()
    student = ReachStudent(0.1, growth=0.002)
    practise(original, student, 537)
    assert original.state()["updates"] == 10
    restored = spdl()
    restored.restore(json.loads(json.dumps(original.snapshot())), original.history(0))
    assert restored.state() == original.state()
    twin = ReachStudent(student.reach, student.growth)
    practise(original, student, 300)
    practise(restored, twin, 300)
    assert restored.state() == original.state()
    assert restored.sample(20) == original.sample(20)


def test_kuka_defaults() -> None:
    teacher = make_teacher("self-paced", KUKA_TASK_SPACE, 0)
    assert mean_of(teacher) == KUKA_TASK_SPACE.easiest()
    target = teacher.state()["target"]["mean"]
    assert target == pytest.approx(KUKA_TASK_SPACE.hardest(), abs=1e-12)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"kl_limit": 0.0}, r"kl_limit\n  Input should be greater than 0"),
        ({"kl_limit": 100.0}, r"kl_limit\n  Input should be less than or equal to 10"),
        ({"update_every": 5}, r"update_every\n  Input should be greater than or equal to 10"),
        ({"update_every": 10**6}, r"update_every\n  Input should be less than or equal to 1000"),
        ({"zeta": 1.5}, r"zeta\n  Input should be less than or equal to 1"),
        ({"initial_spread": 0.0}, r"initial_spread\n  Input should be greater than or equal to 0.001"),
        ({"target": "easiest"}, r"target\n  Input should be 'hardest', 'uniform' or 'box'"),
        ({"reward_range": [2.0, 2.0]}, "reward_range must have low < high"),
        ({"start": {"x": 0.5}}, "start: missing task parameter"),
    ],
)
def test_bad_parameters_are_rejected_by_name(params: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make_teacher("self-paced", SQUARE, 0, params)


def test_needs_its_anchors() -> None:
    bare = TaskSpace([Parameter("x", 0.0, 1.0)])
    with pytest.raises(ValueError, match="start: none given"):
        make_teacher("self-paced", bare, 0)
    with pytest.raises(ValueError, match="target 'hardest' needs a hardest value"):
        make_teacher("self-paced", bare, 0, {"start": {"x": 0.0}})
    assert make_teacher("self-paced", bare, 0, {"start": {"x": 0.0}, "target": "uniform"}).sample(1)
