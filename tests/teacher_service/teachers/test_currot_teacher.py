"""CURROT: particles move toward the target, never further than max_move, never out of what the
student is estimated to master; updates are reproducible from the history and survive a restore."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from common.client.task_space import Parameter, TaskSpace
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.teachers import EpisodeResult, make_teacher
from teacher_service.teachers.currot import (
    LENGTHSCALE_SHARE,
    STAYING,
    TOWARD_BETTER,
    TOWARD_SUCCESS,
    TOWARD_TARGET,
    CurrotTeacher,
    ParticleFit,
    estimate_performance,
)

SQUARE = TaskSpace(
    [
        Parameter("a", 0.0, 1.0, hardest=1.0, easiest=0.0),
        Parameter("b", 0.0, 1.0, hardest=1.0, easiest=0.0),
    ]
)
"""The unit square, so task units and the teacher's unit coordinates are the same numbers."""

SMALL = {"particles": 50, "update_every": 25, "buffer_size": 100, "candidates": 16}


def currot(space: TaskSpace = SQUARE, seed: int = 0, **params: Any) -> CurrotTeacher:
    teacher = make_teacher("currot", space, seed, {**SMALL, **params})
    assert isinstance(teacher, CurrotTeacher)
    return teacher


class GrowingStudent:
    """Succeeds (+10, else 0) on tasks whose mean coordinate is at most its competence, which grows
    with each success up to ``cap``: the success region widens with practice at its frontier."""

    def __init__(self, cap: float) -> None:
        self.cap = cap
        self.successes = 0

    @property
    def competence(self) -> float:
        return min(0.15 + 0.0005 * self.successes, self.cap)

    def masters(self, points: np.ndarray) -> np.ndarray:
        mastered: np.ndarray = points.mean(axis=-1) <= self.competence
        return mastered

    def practise(self, task: dict[str, float]) -> float:
        success = bool(self.masters(np.array([task["a"], task["b"]])))
        self.successes += success
        return 10.0 if success else 0.0


def particles(teacher: CurrotTeacher) -> np.ndarray:
    return np.array([[task["a"], task["b"]] for task in teacher.state()["particles"]])


def test_particles_move_toward_the_target_at_most_max_move_and_never_out_of_the_estimated_mastery() -> None:
    teacher = currot(target="hardest", start="easiest", start_spread=0.05)
    student = GrowingStudent(cap=0.6)
    radius = 0.05 * math.sqrt(2)
    assert teacher.radius == pytest.approx(radius)
    distance_to_target = [float(np.linalg.norm(particles(teacher) - 1.0, axis=-1).mean())]
    reasons = np.zeros(3, dtype=np.int64)
    for _ in range(4000):
        task = teacher.sample(1)[0]
        job = teacher.learn(EpisodeResult(task, student.practise(task)))
        if job is None:
            continue
        before = particles(teacher)
        window = teacher.history(0)[-SMALL["buffer_size"] :]
        fitted = job.run()
        teacher.install(fitted)
        after = particles(teacher)
        reasons += np.bincount(fitted.why, minlength=3)

        assert np.linalg.norm(after - before, axis=-1).max() <= radius + 1e-12
        estimate = estimate_performance(
            window[:, :2], window[:, 2], LENGTHSCALE_SHARE * radius, np.vstack([before, after])
        )
        was_mastered = estimate[: len(before)] >= 5.0
        assert np.all(estimate[len(before) :][was_mastered] >= 5.0 - 1e-9), "a mastered particle left the mastery"
        np.testing.assert_allclose(fitted.values, estimate[len(before) :], atol=1e-9)
        distance_to_target.append(float(np.linalg.norm(after - 1.0, axis=-1).mean()))

    assert student.competence == 0.6, "the student must have grown to its cap"
    assert reasons[TOWARD_TARGET] > 0 and reasons[TOWARD_SUCCESS] > 0
    # The cloud heads for (1, 1) as the student grows, and stops at the edge of what it masters.
    halfway = len(distance_to_target) // 2
    assert distance_to_target[halfway] < distance_to_target[0] - 0.3
    final = particles(teacher)
    assert np.all(final.mean(axis=-1) <= student.competence + radius)
    assert final.mean(axis=-1).mean() > student.competence - 2 * radius
    state = teacher.state()
    assert state["target"] == SQUARE.hardest()
    assert len(state["particle_values"]) == 50 and state["measure"] == "return" and state["bar"] == 5.0
    move = state["moves"][-1]
    assert move["at_results"] == 4000 and move["longest_move"] <= radius + 1e-12
    assert set(move) == {"at_results", "fit", "from", "to", "longest_move", "why"}


def test_before_any_result_reaches_the_bar_particles_head_for_the_better_half() -> None:
    teacher = currot(target="hardest")
    (job,) = [
        job
        for task in teacher.sample(SMALL["update_every"])
        # always below the bar of 5, better toward a = 1
        if (job := teacher.learn(EpisodeResult(task, task["a"] - 2.0))) is not None
    ]
    before = particles(teacher)
    fitted = job.run()
    assert np.all(fitted.why == TOWARD_BETTER), "no result reached the bar: no particle heads for the target"
    moves = fitted.particles - before
    assert np.linalg.norm(moves, axis=-1).max() <= teacher.radius + 1e-12
    assert moves[:, 0].mean() > 0.5 * teacher.radius, "the cloud moves toward the better returns at a = 1"


def test_a_flat_window_below_the_bar_leaves_the_particles_where_they_are() -> None:
    teacher = currot()
    (job,) = [job for task in teacher.sample(SMALL["update_every"]) if (job := teacher.learn(EpisodeResult(task, 0.0)))]
    before = particles(teacher)
    fitted = job.run()
    assert np.all(fitted.why == STAYING) and fitted.particles.tobytes() == before.tobytes()


def test_the_estimate_uses_success_when_every_result_reports_it() -> None:
    flagged, mixed = currot(), currot()
    for step in range(SMALL["update_every"]):
        for teacher in (flagged, mixed):
            task = teacher.sample(1)[0]
            success = None if teacher is mixed and step == 3 else step % 2 == 0
            teacher.learn_and_fit(EpisodeResult(task, 7.0, success=success))
    assert (flagged.state()["measure"], flagged.state()["bar"]) == ("success", 0.5)
    assert (mixed.state()["measure"], mixed.state()["bar"]) == ("return", 5.0)


def test_tasks_come_from_particles_picked_evenly_with_small_noise() -> None:
    teacher = currot(noise=0.002)
    tasks = np.array([[task["a"], task["b"]] for task in teacher.sample(2000)])
    offsets = np.abs(tasks[:, None, :] - particles(teacher)[None, :, :])
    assert offsets.max(axis=-1).min(axis=1).max() <= 0.002 + 1e-12
    picks = np.bincount(offsets.max(axis=-1).argmin(axis=1), minlength=50)
    assert picks.min() > 15 and picks.max() < 70, "each of the 50 particles is picked about 40 times in 2000"


def test_tasks_depend_on_the_seed_and_index_only() -> None:
    first, second = currot(seed=5), currot(seed=5)
    assert first.sample(7) + first.sample(13) == second.sample(20)
    assert currot(seed=6).sample(20) != currot(seed=5).sample(20)


def due_jobs(teacher: CurrotTeacher, results: int, seed: int) -> list[Any]:
    rng = np.random.default_rng(seed)
    jobs = []
    for _ in range(results):
        task = teacher.sample(1)[0]
        job = teacher.learn(EpisodeResult(task, float(10 * task["a"] * rng.random())))
        if job is not None:
            jobs.append(job)
    return jobs


def test_a_fit_due_before_a_snapshot_is_rebuilt_exactly_even_after_an_earlier_fit_was_installed() -> None:
    teacher = currot(target="hardest")
    first, second = due_jobs(teacher, 2 * SMALL["update_every"], seed=1)
    teacher.install(first.run())  # installed after the second fit fell due: that one started from the start
    snapshot = json.loads(json.dumps(teacher.snapshot(), allow_nan=False))
    restored = currot(target="hardest")
    restored.restore(snapshot, teacher.history(0))

    lost = restored.refit_job(second.index).run()
    live = second.run()
    assert lost.particles.tobytes() == live.particles.tobytes()
    assert lost.values.tobytes() == live.values.tobytes()
    restored.install(lost)
    teacher.install(live)
    assert restored.state() == teacher.state()
    assert restored.sample(30) == teacher.sample(30)
    with pytest.raises(ValueError, match="fit 1 was superseded"):
        teacher.refit_job(1)
    with pytest.raises(ValueError, match="fit 2 has not fallen due"):
        teacher.refit_job(2)


def test_a_newer_fit_may_skip_ahead_and_an_older_one_is_then_stale() -> None:
    teacher = currot()
    first, second = due_jobs(teacher, 2 * SMALL["update_every"], seed=2)
    teacher.install(second.run())
    assert teacher.state()["last_fit_index"] == 1
    with pytest.raises(ValueError, match="fit 0 is stale: fit 1 is installed"):
        teacher.install(first.run())
    with pytest.raises(TypeError, match="expected the ParticleFit"):
        teacher.install("particles")


def test_a_stored_fit_installs_bit_for_bit() -> None:
    teacher = currot()
    (job,) = due_jobs(teacher, SMALL["update_every"], seed=3)
    fitted = job.run()
    restored = teacher.import_fit(json.loads(json.dumps(teacher.export_fit(fitted))))
    assert isinstance(restored, ParticleFit)
    for name in ("particles", "values", "why"):
        assert getattr(restored, name).tobytes() == getattr(fitted, name).tobytes()
    assert (restored.index, restored.measure, restored.bar) == (fitted.index, fitted.measure, fitted.bar)
    with pytest.raises(ValueError, match="needs particles of shape"):
        teacher.import_fit({**teacher.export_fit(fitted), "particles": [[0.0, 1.0]]})


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"update_every": 50, "buffer_size": 40}, r"buffer_size \(40\) cannot be less than update_every \(50\)"),
        ({"particles": 501}, r"particles\n  Input should be less than or equal to 500"),
        ({"particles": 1}, r"particles\n  Input should be greater than or equal to 2"),
        ({"max_move": 0.0}, r"max_move\n  Input should be greater than 0"),
        ({"buffer_size": 2001}, r"buffer_size\n  Input should be less than or equal to 2000"),
        ({"candidates": 65}, r"candidates\n  Input should be less than or equal to 64"),
        ({"delta": float("inf")}, r"delta\n  Input should be a finite number"),
        ({"success_delta": 1.5}, r"success_delta\n  Input should be less than or equal to 1"),
        ({"noise": -0.1}, r"noise\n  Input should be greater than or equal to 0"),
        ({"target": "easiest"}, r"target\n  Input should be 'uniform' or 'hardest'"),
        ({"start": "hardest"}, r"start\n  Input should be 'uniform' or 'easiest'"),
    ],
)
def test_bad_parameters_are_rejected_by_name(params: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make_teacher("currot", KUKA_TASK_SPACE, 0, params)


def test_a_target_or_start_anchor_must_exist() -> None:
    unanchored = TaskSpace([Parameter("x", 0.0, 1.0)])
    make_teacher("currot", unanchored, 0)  # the defaults need no anchors
    with pytest.raises(ValueError, match="target: this task space defines no hardest value"):
        make_teacher("currot", unanchored, 0, {"target": "hardest"})
    with pytest.raises(ValueError, match="start: this task space defines no easiest value"):
        make_teacher("currot", unanchored, 0, {"start": "easiest"})
