"""CURROT: particles move toward the target, never further than max_move unless replaced from the
success buffer, never out of what the student is estimated to master when they can stay in it;
updates are reproducible from the history and survive a restore."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from common.client.task_space import Parameter, TaskSpace
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.teachers import EpisodeResult, make_teacher
from teacher_service.teachers.algorithms.currot import (
    REPLACED_TO_BEST,
    REPLACED_TOWARD_TARGET,
    TOWARD_TARGET,
    ParticleFit,
    update_successes,
)
from teacher_service.teachers.currot import CurrotTeacher

SQUARE = TaskSpace(
    [
        Parameter("a", 0.0, 1.0, hardest=1.0, easiest=0.0),
        Parameter("b", 0.0, 1.0, hardest=1.0, easiest=0.0),
    ]
)
"""The unit square, so task units and the teacher's unit coordinates are the same numbers."""

SMALL = {"particles": 50, "update_every": 25, "candidates": 16}


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


@pytest.mark.parametrize("below_bar", ["jump", "walk"])
def test_particles_head_for_the_target_within_the_estimated_mastery_and_bounded_moves(below_bar: str) -> None:
    teacher = currot(target="hardest", start="easiest", start_spread=0.05, delta=5.0, below_bar=below_bar)
    student = GrowingStudent(cap=0.6)
    radius = 0.05 * math.sqrt(2)
    assert teacher.radius == pytest.approx(radius)
    distance_to_target = [float(np.linalg.norm(particles(teacher) - 1.0, axis=-1).mean())]
    reasons = np.zeros(4, dtype=np.int64)
    for _ in range(4000):
        task = teacher.sample(1)[0]
        job = teacher.learn(EpisodeResult(task, student.practise(task)))
        if job is None:
            continue
        before = particles(teacher)
        fitted = job.run()
        teacher.install(fitted)
        after = particles(teacher)
        reasons += np.bincount(fitted.why, minlength=4)

        moves = np.linalg.norm(after - before, axis=-1)
        kept = fitted.why < REPLACED_TOWARD_TARGET
        assert np.all(moves[kept] <= radius + 1e-12), "a particle at the bar moved further than max_move"
        if below_bar == "walk":
            assert np.all(moves <= 2 * radius + 1e-12), "a walk and a move of at most max_move each"
        toward = (fitted.why == TOWARD_TARGET) | (fitted.why == REPLACED_TOWARD_TARGET)
        assert np.all(fitted.values[toward] >= 5.0), "a particle that could stay at the bar left it"
        distance_to_target.append(float(np.linalg.norm(after - 1.0, axis=-1).mean()))

    assert student.competence == 0.6, "the student must have grown to its cap"
    assert reasons[TOWARD_TARGET] > 0 and reasons[REPLACED_TOWARD_TARGET] + reasons[REPLACED_TO_BEST] > 0
    # The cloud heads for (1, 1) as the student grows, and stops at the edge of what it masters.
    halfway = len(distance_to_target) // 2
    assert distance_to_target[halfway] < distance_to_target[0] - 0.3
    final = particles(teacher)
    assert np.mean(final.mean(axis=-1) <= student.competence + radius) > 0.9
    assert final.mean(axis=-1).mean() > student.competence - 2 * radius
    state = teacher.state()
    assert state["target"] == SQUARE.hardest() and state["threshold_reached"]
    assert len(state["particle_values"]) == 50 and state["measure"] == "return" and state["bar"] == 5.0
    assert state["success_buffer"] == 50 and state["failures_kept"] == 50
    move = state["moves"][-1]
    assert move["at_results"] == 4000
    assert set(move) == {"at_results", "fit", "from", "to", "longest_move", "why"}


def test_when_nothing_pays_anywhere_the_particles_keep_exploring_the_box() -> None:
    """The stall of the version before issue 48: every result 0, so nothing is better than anything;
    the authors' noisy resampling of the success buffer still spreads the particles over the box."""
    teacher = currot(delta=0.5)
    seen = []
    for _ in range(10):
        before = particles(teacher)
        (job,) = [
            job for task in teacher.sample(SMALL["update_every"]) if (job := teacher.learn(EpisodeResult(task, 0.0)))
        ]
        fitted = job.run()
        teacher.install(fitted)
        assert np.all(fitted.why == REPLACED_TO_BEST), "every particle is below the bar and none can reach it"
        assert np.linalg.norm(fitted.particles - before, axis=-1).mean() > 0.1
        seen.append(fitted.particles)
    cells = {tuple(cell) for cell in (np.concatenate(seen) * 10).astype(int)}
    assert len(cells) > 80, "ten updates reach most of the 100 cells of the box"
    assert not teacher.state()["threshold_reached"] and teacher.state()["failures_kept"] == 0


def test_a_rare_success_draws_the_particles_to_it() -> None:
    """One corner pays; the success buffer keeps its results and the particles below the bar are
    replaced from it, so the cloud gathers there within a few updates."""
    teacher = currot(delta=0.5, particles=100, update_every=50)
    for _ in range(40):
        for task in teacher.sample(50):
            teacher.learn_and_fit(EpisodeResult(task, 1.0 if max(task.values()) < 0.1 else 0.0))
    near = np.max(particles(teacher), axis=1) < 0.2
    assert near.mean() > 0.5, f"only {near.mean():.0%} of the particles gathered at the paying corner"


def test_the_success_buffer_keeps_the_better_half_until_its_median_passes_the_bar() -> None:
    def unused() -> np.ndarray:
        raise AssertionError("target samples are needed only once the buffer is full of successes")

    one = np.ones(1)
    batch = np.array([[0.1, 0.0], [0.2, 0.3], [0.3, 0.1], [0.4, 0.2]])
    buffer, failed, reached = update_successes(np.empty((0, 2)), batch, 1, 0.5, False, 3, unused, one)
    # the first batch joins whole (nothing to beat), the buffer keeps its best 3, sorted
    assert buffer[:, 1].tolist() == [0.1, 0.2, 0.3] and failed.tolist() == [True, False, False, False]
    assert not reached
    better = np.array([[0.5, 0.9], [0.6, 0.05], [0.7, 0.8]])
    buffer, failed, reached = update_successes(buffer, better, 1, 0.5, False, 3, unused, one)
    assert buffer[:, 1].tolist() == [0.3, 0.8, 0.9] and failed.tolist() == [False, True, False] and not reached
    # its median (0.8) is above the bar: from the next update on only successes join, replacing failures
    assert update_successes(buffer, better, 1, 0.5, False, 3, unused, one)[2]
    buffer, failed, reached = update_successes(
        buffer, np.array([[0.9, 0.6], [0.95, 0.1]]), 1, 0.5, True, 3, unused, one
    )
    assert sorted(buffer[:, 1].tolist()) == [0.6, 0.8, 0.9] and failed.tolist() == [False, True] and reached


def test_a_full_buffer_of_successes_keeps_those_an_assignment_to_target_samples_picks() -> None:
    buffer = np.array([[0.0, 1.0], [0.5, 1.0]])
    targets = np.array([[1.0], [0.9]])
    kept, failed, _ = update_successes(
        buffer, np.array([[1.0, 1.0], [0.2, 1.0]]), 1, 0.5, True, 2, lambda: targets, np.ones(1)
    )
    assert sorted(kept[:, 0].tolist()) == [0.5, 1.0] and failed.tolist() == [False, True]


def test_the_estimate_uses_success_when_every_result_reports_it() -> None:
    flagged, mixed = currot(delta=5.0), currot(delta=5.0)
    for step in range(SMALL["update_every"]):
        for teacher in (flagged, mixed):
            task = teacher.sample(1)[0]
            success = None if teacher is mixed and step == 3 else step % 2 == 0
            teacher.learn_and_fit(EpisodeResult(task, 7.0, success=success))
    assert (flagged.state()["measure"], flagged.state()["bar"]) == ("success", 0.5)
    assert (mixed.state()["measure"], mixed.state()["bar"]) == ("return", 5.0)


def test_without_delta_the_return_bar_is_learned_from_the_returns_seen() -> None:
    teacher = currot()
    assert teacher.params.delta is None
    for task in teacher.sample(SMALL["update_every"]):
        teacher.learn_and_fit(EpisodeResult(task, 3.0))
    # every return the same: no bar yet, so no particle counts as mastered
    assert teacher.state()["bar"] is None and teacher.state()["next_bar"]["source"] == "learned from the returns seen"
    for index, task in enumerate(teacher.sample(SMALL["update_every"])):
        teacher.learn_and_fit(EpisodeResult(task, -1.0 if index == 0 else 7.0))
    # half way (success_delta) from the lowest to the highest return seen
    assert teacher.state()["bar"] == pytest.approx(3.0)
    assert currot(success_delta=0.75).params.success_delta == 0.75


def test_raw_distances_measure_the_move_in_the_tasks_own_units() -> None:
    narrow = TaskSpace([Parameter("a", 0.0, 4.0), Parameter("b", 0.0, 0.1)])
    assert currot(narrow).radius == pytest.approx(0.05 * math.sqrt(2))
    raw = currot(narrow, distances="raw", delta=0.5)
    assert raw.radius == pytest.approx(0.05 * math.sqrt(16.01))
    for _ in range(4):
        for task in raw.sample(SMALL["update_every"]):
            raw.learn_and_fit(EpisodeResult(task, float(task["a"] < 2.0)))
    assert raw.state()["moves"][-1]["longest_move"] > 0.0


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
    teacher = currot(target="hardest", delta=5.0)
    first, second = due_jobs(teacher, 2 * SMALL["update_every"], seed=1)
    teacher.install(first.run())  # installed after the second fit fell due: that one started from the start
    snapshot = json.loads(json.dumps(teacher.snapshot(), allow_nan=False))
    restored = currot(target="hardest", delta=5.0)
    restored.restore(snapshot, teacher.history(teacher.history_kept_from(snapshot)))

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
    assert (restored.index, restored.measure, restored.bar, restored.threshold_reached) == (
        fitted.index,
        fitted.measure,
        fitted.bar,
        fitted.threshold_reached,
    )
    with pytest.raises(ValueError, match="needs particles of shape"):
        teacher.import_fit({**teacher.export_fit(fitted), "particles": [[0.0, 1.0]]})


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"below_bar": "stay"}, r"below_bar\n  Input should be 'jump' or 'walk'"),
        ({"distances": "scaled"}, r"distances\n  Input should be 'unit' or 'raw'"),
        ({"particles": 501}, r"particles\n  Input should be less than or equal to 500"),
        ({"particles": 1}, r"particles\n  Input should be greater than or equal to 2"),
        ({"max_move": 0.0}, r"max_move\n  Input should be greater than 0"),
        ({"buffer_size": 2001}, r"buffer_size\n  Input should be less than or equal to 2000"),
        ({"candidates": 129}, r"candidates\n  Input should be less than or equal to 128"),
        ({"delta": float("inf")}, r"delta\n  Input should be a finite number"),
        ({"success_delta": 1.5}, r"success_delta\n  Input should be less than or equal to 1"),
        ({"noise": -0.1}, r"noise\n  Input should be greater than or equal to 0"),
        ({"target": "easiest"}, r"target\n  Input should be 'uniform', 'hardest' or 'box'"),
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
