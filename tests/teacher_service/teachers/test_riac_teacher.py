"""RIAC: regions split where progress differs, full leaves that cannot split discard, the three
sampling modes, and sampling that follows a student's progress."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from common.client.task_space import Parameter, TaskSpace
from teacher_service.teachers import EpisodeResult, Teacher, make_teacher
from teacher_service.teachers.riac import RiacTeacher, progress

SQUARE = TaskSpace([Parameter("x", 0.0, 1.0), Parameter("y", -2.0, 2.0)])


def riac(seed: int = 0, **params: Any) -> RiacTeacher:
    teacher = make_teacher("riac", SQUARE, seed, params)
    assert isinstance(teacher, RiacTeacher)
    return teacher


def learning_on_the_left(task: dict[str, float], episode: int) -> float:
    """Reward grows with practice where x < 0.3 (but stays low), and is high and flat elsewhere."""
    return 0.2 * episode / 2000 if task["x"] < 0.3 else 0.8


def test_progress_compares_the_older_and_newer_half_of_the_window() -> None:
    assert progress(np.array([1.0, 2.0]), 10) == 0.0
    assert progress(np.array([0.0, 0.0, 1.0, 1.0]), 10) == 1.0
    assert progress(np.array([0.0, 1.0, 1.0]), 10) == 0.5, "the older half takes the odd reward"
    assert progress(np.array([5.0, 0.0, 0.0, 3.0, 3.0]), 4) == 3.0, "only the window counts"


def test_a_full_leaf_splits_into_two_populated_halves_of_the_box() -> None:
    teacher = riac(max_region_size=20, min_region_results=3)
    for episode, task in enumerate(teacher.sample(21)):
        teacher.learn_and_fit(EpisodeResult(task, learning_on_the_left(task, 100 * episode)))
    state = teacher.state()
    assert state["splits"] == 1 and state["discards"] == 0
    root, lower, upper = state["regions"]
    assert root == {**root, "low": {"x": 0.0, "y": -2.0}, "high": {"x": 1.0, "y": 2.0}, "results": 21, "leaf": False}
    assert lower["leaf"] and upper["leaf"]
    assert lower["results"] >= 3 and upper["results"] >= 3 and lower["results"] + upper["results"] == 21
    (cut,) = [name for name in ("x", "y") if lower["high"][name] != root["high"][name]]
    assert lower["high"][cut] == upper["low"][cut]
    width = root["high"][cut] - root["low"][cut]
    assert min(lower["high"][cut] - lower["low"][cut], upper["high"][cut] - upper["low"][cut]) >= width / 15
    assert sum(region["sampling_probability"] for region in state["regions"]) == pytest.approx(1.0)

    task = {"x": 0.01, "y": -1.99}
    teacher.learn_and_fit(EpisodeResult(task, 0.0))
    assert teacher.state()["regions"][0]["results"] == 21, "a region keeps max_region_size + 1 results"
    assert lower["results"] + 1 == teacher.state()["regions"][1]["results"], "a result joins each region holding it"


def test_a_leaf_with_no_qualifying_cut_drops_its_oldest_results() -> None:
    teacher = riac(max_region_size=20, discard_ratio=0.25)
    for episode in range(21):
        teacher.learn_and_fit(EpisodeResult({"x": 0.5, "y": 0.0}, float(episode)))
    state = teacher.state()
    assert state["splits"] == 0 and state["discards"] == 1
    assert state["regions"][0]["results"] == 21 - 5


def test_the_tree_stops_growing_at_max_regions() -> None:
    teacher = riac(max_region_size=10, max_regions=5)
    for episode, task in enumerate(teacher.sample(400)):
        teacher.learn_and_fit(EpisodeResult(task, learning_on_the_left(task, 5 * episode)))
    state = teacher.state()
    assert state["splits"] == 2 and len(state["regions"]) == 5 and state["discards"] > 0


def test_mutations_move_the_lowest_reward_task_of_a_region() -> None:
    teacher = riac(mutation_ratio=1.0, random_task_ratio=0.0, mutation_std=0.05)
    teacher.sample(1)
    for episode in range(10):
        x = 0.1 * episode
        teacher.learn_and_fit(EpisodeResult({"x": x, "y": 0.0}, 1.0 if episode != 4 else 0.0))
    tasks = teacher.sample(1000)
    xs = np.array([task["x"] for task in tasks])
    ys = np.array([task["y"] for task in tasks])
    assert np.mean(xs) == pytest.approx(0.4, abs=0.01)
    assert np.std(xs) == pytest.approx(0.05, rel=0.1)
    assert np.std(ys) == pytest.approx(0.05 * 4, rel=0.1), "the spread is a share of each dimension's width"


def test_sampling_concentrates_where_reward_is_changing() -> None:
    teacher = riac(seed=5)
    for episode in range(3000):
        task = teacher.sample(1)[0]
        teacher.learn_and_fit(EpisodeResult(task, learning_on_the_left(task, episode)))
    state = teacher.state()
    assert state["splits"] >= 5
    xs = np.array([task["x"] for task in teacher.sample(3000)])
    # Uniform sampling puts 30% of tasks on the strip.
    assert np.mean(xs < 0.3) > 0.55
    likeliest = max(state["regions"], key=lambda region: region["sampling_probability"])
    assert likeliest["high"]["x"] <= 0.35


@pytest.mark.parametrize("leaves_only", [False, True])
def test_regions_are_picked_by_progress_among_all_regions_or_leaves(leaves_only: bool) -> None:
    teacher = riac(max_region_size=20, leaves_only=leaves_only)
    for episode, task in enumerate(teacher.sample(200)):
        teacher.learn_and_fit(EpisodeResult(task, learning_on_the_left(task, 10 * episode)))
    regions = teacher.state()["regions"]
    picked = [region for region in regions if region["sampling_probability"] > 0]
    assert picked and all(region["progress"] > 0 for region in picked)
    assert any(not region["leaf"] for region in picked) != leaves_only
    total = sum(region["progress"] for region in regions if region["leaf"] or not leaves_only)
    for region in picked:
        assert region["sampling_probability"] == pytest.approx(region["progress"] / total)


def test_a_restored_teacher_rebuilds_regions_that_split_and_discarded() -> None:
    teacher = riac(max_region_size=10, max_regions=7)
    for episode, task in enumerate(teacher.sample(300)):
        stuck = episode % 3 == 0  # a third of the results pile up on one point, which no cut can separate
        teacher.learn_and_fit(
            EpisodeResult({"x": 0.9, "y": 1.9} if stuck else task, learning_on_the_left(task, episode))
        )
    state = teacher.state()
    assert state["splits"] == 3 and state["discards"] > 0

    restored = riac(max_region_size=10, max_regions=7)
    snapshot = json.loads(json.dumps(teacher.snapshot()))
    kept_from = Teacher.history_kept_from(snapshot)
    assert 0 < kept_from < 300, "the regions hold only recent rows"
    restored.restore(snapshot, teacher.history(kept_from))
    assert restored.state() == state
    assert restored.sample(200) == teacher.sample(200)
