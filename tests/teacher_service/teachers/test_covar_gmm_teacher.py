"""Covar-GMM: bootstrap and fit cadence, the (task, time, reward) points, component choice by the
time-reward covariance, and sampling that follows a student's progress."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from common.client.task_space import Parameter, TaskSpace
from teacher_service.teachers import EpisodeResult, make_teacher
from teacher_service.teachers.covar_gmm import CovarGmmTeacher
from teacher_service.teachers.mixture import MixtureFit

SQUARE = TaskSpace([Parameter("x", 0.0, 1.0), Parameter("y", -2.0, 2.0)])


def covar_gmm(seed: int = 0, **params: Any) -> CovarGmmTeacher:
    teacher = make_teacher("covar-gmm", SQUARE, seed, params)
    assert isinstance(teacher, CovarGmmTeacher)
    return teacher


def learning_on_the_left(task: dict[str, float], episode: int) -> float:
    """Reward grows with practice time where x < 0.3 (but stays low), and is high and flat elsewhere:
    only the left strip shows progress."""
    return 0.2 * episode / 2000 if task["x"] < 0.3 else 0.8


def test_the_first_fit_comes_due_after_fit_rate_results_over_task_time_and_reward() -> None:
    teacher = covar_gmm(fit_rate=20, max_components=3)
    jobs = [teacher.learn(EpisodeResult(task, float(i))) for i, task in enumerate(teacher.sample(20))]
    assert jobs[:-1] == [None] * 19 and jobs[-1] is not None
    rows = teacher.history(0)
    assert rows.shape == (20, 4)
    np.testing.assert_array_equal(rows[:, 2], np.arange(20) / 20)
    np.testing.assert_array_equal(rows[:, 3], np.arange(20.0))
    assert rows[:, :2].min() >= 0.0 and rows[:, :2].max() <= 1.0, "tasks are fitted rescaled to [0, 1]"
    assert teacher.state()["bootstrapping"]

    fit = jobs[-1].run()
    teacher.install(fit)
    assert teacher.state()["fits"] == 1 and teacher.state()["components"]
    with pytest.raises(ValueError, match="stale"):
        teacher.install(fit)
    for i, task in enumerate(teacher.sample(20)):
        teacher.learn(EpisodeResult(task, float(i)))
    np.testing.assert_array_equal(teacher.history(20)[:, 2], np.arange(20) / 20, "time restarts with each batch")


def hand_made(covariance_signs: tuple[float, float]) -> MixtureFit:
    """Two narrow components over (x, y, time, reward) in unit task coordinates, at x = 0.1 and 0.9,
    whose time-reward covariances have the given signs."""
    covariances = []
    for sign in covariance_signs:
        covariance = np.eye(4) * 1e-4
        covariance[2, 3] = covariance[3, 2] = sign * 5e-5
        covariances.append(covariance)
    return MixtureFit(
        index=0,
        weights=np.array([0.5, 0.5]),
        means=np.array([[0.1, 0.5, 0.5, 0.2], [0.9, 0.5, 0.5, 0.9]]),
        covariances=np.array(covariances),
    )


@pytest.mark.parametrize(
    ("signs", "absolute", "left_share"),
    [((1.0, -1.0), False, 1.0), ((-1.0, 1.0), False, 0.0), ((1.0, -1.0), True, 0.5), ((-1.0, -1.0), False, 0.5)],
)
def test_components_are_picked_by_their_time_reward_covariance(
    signs: tuple[float, float], absolute: bool, left_share: float
) -> None:
    teacher = covar_gmm(random_task_ratio=0.0, absolute_progress=absolute)
    teacher.install(hand_made(signs))
    xs = np.array([task["x"] for task in teacher.sample(2000)])
    assert np.all((xs < 0.2) | (xs > 0.8)), "tasks come from the components' Gaussians"
    assert np.mean(xs < 0.5) == pytest.approx(left_share, abs=0.05)
    probabilities = [c["sampling_probability"] for c in teacher.state()["components"]]
    assert probabilities == pytest.approx([left_share, 1 - left_share])


def test_sampling_concentrates_where_reward_is_changing() -> None:
    teacher = covar_gmm(seed=5)
    for episode in range(1000):
        task = teacher.sample(1)[0]
        teacher.learn_and_fit(EpisodeResult(task, learning_on_the_left(task, episode)))
    assert teacher.state()["fits"] == 4
    xs = np.array([task["x"] for task in teacher.sample(3000)])
    # Uniform sampling puts 30% of tasks on the strip; the random share alone puts 20% * 30% there.
    assert np.mean(xs < 0.3) > 0.6
    best = max(teacher.state()["components"], key=lambda c: c["sampling_probability"])
    assert best["mean"]["x"] < 0.3 and best["time_reward_covariance"] > 0


def test_components_are_reported_in_task_units() -> None:
    teacher = covar_gmm(random_task_ratio=0.0)
    teacher.install(hand_made((1.0, 1.0)))
    (left, right) = teacher.state()["components"]
    assert left["mean"] == pytest.approx({"x": 0.1, "y": 0.0})
    assert right["mean"] == pytest.approx({"x": 0.9, "y": 0.0})
    np.testing.assert_allclose(left["covariance"], [[1e-4, 0.0], [0.0, 16e-4]])
    assert left["time_reward_covariance"] == pytest.approx(5e-5)


def test_a_fit_exports_exactly_and_a_lost_fit_is_rebuilt() -> None:
    teacher = covar_gmm(fit_rate=30, max_components=4)
    jobs = []
    for episode, task in enumerate(teacher.sample(90)):
        job = teacher.learn(EpisodeResult(task, learning_on_the_left(task, episode)))
        if job is not None:
            jobs.append(job)
    fit = jobs[1].run()
    again = teacher.import_fit(json.loads(json.dumps(teacher.export_fit(fit))))
    for field in ("weights", "means", "covariances"):
        np.testing.assert_array_equal(getattr(again, field), getattr(fit, field))
    assert again.aic_by_components == fit.aic_by_components
    rebuilt = teacher.refit_job(1).run()
    np.testing.assert_array_equal(rebuilt.means, fit.means)
    with pytest.raises(ValueError, match="has not fallen due"):
        teacher.refit_job(3)
    teacher.install(jobs[2].run())  # skipping fits 0 and 1, as a superseded queue does
    assert teacher.state()["last_fit_index"] == 2
    with pytest.raises(ValueError, match="means of shape"):
        teacher.import_fit({**teacher.export_fit(fit), "means": [[0.0, 0.0]]})
