"""The learnability teacher: it replays tasks the student solves about half the time, keeps its
fresh share, stays bounded, reads success or a return bar on any scale, and survives a restart."""

from __future__ import annotations

import json
from collections.abc import Callable

import numpy as np
import pytest
from pydantic import ValidationError

from common.client.task_space import Parameter, Task, TaskSpace
from teacher_service.teachers import EpisodeResult, Teacher, make_teacher
from teacher_service.teachers.learnability import LearnabilityTeacher

SPACE = TaskSpace([Parameter("difficulty", 0.0, 1.0), Parameter("noise", -5.0, 5.0)])


def half_solved_band(task: Task, draw: float) -> bool:
    """Easy tasks (difficulty < 0.4) always succeed, hard ones (> 0.6) never, the band between half the time."""
    level = task["difficulty"]
    return level < 0.4 or (level <= 0.6 and draw < 0.5)


def train(
    teacher: Teacher,
    episodes: int,
    outcome: Callable[[Task, float], bool] = half_solved_band,
    reward: Callable[[bool], float] | None = None,
    seed: int = 0,
) -> None:
    """Play ``episodes``: report ``success`` itself, or only the return ``reward(success)`` when given."""
    rng = np.random.default_rng(seed)
    for _ in range(episodes // 10):
        for task in teacher.sample(10):
            solved = outcome(task, float(rng.random()))
            if reward is None:
                teacher.learn_and_fit(EpisodeResult(task, 1.0 if solved else 0.0, success=solved))
            else:
                teacher.learn_and_fit(EpisodeResult(task, reward(solved)))


def split_by_origin(teacher: LearnabilityTeacher, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Difficulties of the next ``count`` tasks, replayed from the pool and fresh."""
    pool = {tuple(task.values()) for task in teacher.state()["pool"]}
    tasks = teacher.sample(count)
    replayed = np.array([t["difficulty"] for t in tasks if tuple(t.values()) in pool])
    fresh = np.array([t["difficulty"] for t in tasks if tuple(t.values()) not in pool])
    return replayed, fresh


def build(seed: int = 1, **params: object) -> LearnabilityTeacher:
    teacher = make_teacher("learnability", SPACE, seed, params)
    assert isinstance(teacher, LearnabilityTeacher)
    return teacher


def test_it_replays_the_tasks_solved_about_half_the_time() -> None:
    teacher = build()
    train(teacher, 3000)
    replayed, fresh = split_by_origin(teacher, 4000)
    in_band = np.mean((replayed > 0.35) & (replayed < 0.65))
    assert in_band > 0.8, f"only {in_band:.0%} of replays near the half-solved band (uniform: 30%)"
    assert np.mean((fresh > 0.35) & (fresh < 0.65)) == pytest.approx(0.3, abs=0.06), "fresh tasks stay uniform"
    state = teacher.state()
    best = int(np.argmax(state["pool_probability"]))
    assert 0.35 < state["pool"][best]["difficulty"] < 0.65
    assert state["pool_learnability"][best] == pytest.approx(0.25, abs=0.05)


@pytest.mark.parametrize("fresh_share", [0.0, 0.2, 0.6])
def test_the_fresh_share_is_respected(fresh_share: float) -> None:
    teacher = build(fresh_share=fresh_share)
    train(teacher, 500)
    replayed, fresh = split_by_origin(teacher, 5000)
    assert len(fresh) / 5000 == pytest.approx(fresh_share, abs=0.02)
    assert sum(teacher.state()["pool_probability"]) == pytest.approx(1.0 - fresh_share)


def test_every_task_is_uniform_until_the_first_pool() -> None:
    teacher = build(update_every=100)
    train(teacher, 90)
    assert teacher.state()["pool"] == [] and teacher.state()["refreshes"] == 0
    train(teacher, 10)
    assert len(teacher.state()["pool"]) == 200 and teacher.state()["refreshes"] == 1


def test_pool_buffer_and_replays_stay_bounded() -> None:
    teacher = build(pool_size=30, top_k=5, buffer_size=100, update_every=10, replay_share=1.0)
    for _ in range(20):  # a store writes the new history rows and releases them, as the service does
        train(teacher, 100)
        teacher.release_history(teacher.history_size)
    assert teacher.history_held <= 4 * 100, "only about the last 100 results stay in memory"
    state = teacher.state()
    assert len(state["pool"]) == len(state["pool_success"]) == 30
    assert np.count_nonzero(state["pool_probability"]) <= 5, "only the top 5 are replayed"
    # With every candidate a replay, the pool comes from the last 100 results alone.
    recent = {tuple(SPACE.from_array(SPACE.from_unit(row[:2])).values()) for row in teacher.history(1900)}
    assert {tuple(task.values()) for task in state["pool"]} <= recent


def test_the_same_seed_gives_the_same_tasks_and_another_seed_other_tasks() -> None:
    first, second, other = build(seed=4), build(seed=4), build(seed=5)
    for teacher in (first, second, other):
        train(teacher, 400)
    assert first.sample(50) == second.sample(50)
    assert first.sample(50) != other.sample(50)


def test_without_success_the_bar_is_the_midpoint_of_the_held_returns_on_any_scale() -> None:
    unit = build(buffer_size=300)
    train(unit, 1000, reward=lambda solved: 1.0 if solved else 0.0)
    assert unit.state()["return_bar"] == pytest.approx(0.5)
    scaled = build(buffer_size=300)
    train(scaled, 1000, reward=lambda solved: 4000.0 if solved else -2000.0)
    assert scaled.state()["return_bar"] == pytest.approx(1000.0)
    assert scaled.state()["pool_success"] == unit.state()["pool_success"]
    assert scaled.sample(200) == unit.sample(200), "the scale of returns changes nothing"
    replayed, _ = split_by_origin(scaled, 2000)
    assert np.mean((replayed > 0.35) & (replayed < 0.65)) > 0.8


def test_a_given_return_bar_is_used_and_success_beats_the_return() -> None:
    high_bar = build(return_bar=10.0)
    train(high_bar, 500, reward=lambda solved: 1.0 if solved else 0.0)
    assert high_bar.state()["return_bar"] == 10.0
    assert max(high_bar.state()["pool_success"]) < 0.1, "no return reaches the bar: nothing succeeds"

    flagged = build()
    rng = np.random.default_rng(3)
    for _ in range(100):  # returns that say nothing: success alone tells the band
        for task in flagged.sample(10):
            solved = half_solved_band(task, float(rng.random()))
            flagged.learn_and_fit(EpisodeResult(task, float(rng.uniform(-50.0, 50.0)), success=solved))
    assert flagged.state()["return_bar"] is None
    replayed, _ = split_by_origin(flagged, 2000)
    assert np.mean((replayed > 0.35) & (replayed < 0.65)) > 0.8


def test_equal_returns_count_as_no_success_and_leave_sampling_even() -> None:
    teacher = build(top_k=None)
    train(teacher, 500, reward=lambda solved: 3.0)
    state = teacher.state()
    assert state["return_bar"] == 3.0
    assert len(set(state["pool_success"])) == 1, "the prior alone: every candidate alike"
    assert np.ptp(state["pool_probability"]) < 1e-12


def test_a_restored_teacher_hands_out_the_same_next_tasks() -> None:
    original = build(buffer_size=200)
    train(original, 730, reward=lambda solved: 5.0 if solved else -1.0)
    original.sample(3)  # handed out, no result yet
    snapshot = json.loads(json.dumps(original.snapshot(), allow_nan=False))
    kept_from = Teacher.history_kept_from(snapshot)
    assert kept_from == 730 - 200
    restored = build(buffer_size=200)
    restored.restore(snapshot, original.history(kept_from))
    assert restored.state() == original.state()
    train(restored, 300, reward=lambda solved: 5.0 if solved else -1.0, seed=9)
    train(original, 300, reward=lambda solved: 5.0 if solved else -1.0, seed=9)
    assert restored.sample(40) == original.sample(40)


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"pool_size": 0}, "pool_size"),
        ({"pool_size": 5000}, "pool_size"),
        ({"buffer_size": 10**6}, "buffer_size"),
        ({"neighbours": 65}, "neighbours"),
        ({"fresh_share": 1.5}, "fresh_share"),
        ({"return_bar": float("nan")}, "return_bar"),
        ({"top_k": 0}, "top_k"),
        ({"unknown": 1}, "unknown"),
    ],
)
def test_out_of_bounds_parameters_are_refused_by_name(params: dict[str, object], field: str) -> None:
    with pytest.raises(ValidationError, match=field):
        build(**params)
