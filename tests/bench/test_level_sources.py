"""The level side-by-side's stand-ins for the teacher service: uniform levels with no service at all, and
Syllabus 0.7's curricula in a Ray actor, each fed through a real worker or real reports."""

from __future__ import annotations

import numpy as np
import pytest
import ray
import torch

from bench.level_sources import BLOCK, SyllabusCurriculum, SyllabusLevels, UniformLevels
from common.policy.actor_critic import ActorCritic, PolicySpec, capture_snapshot
from common.policy.normalizer import RunningNormalizer
from common.policy.trajectory import EpisodeStats
from rollout_worker.actor import RolloutWorker, WorkerSettings

LEVELS = 12


def test_uniform_levels_cover_the_training_set_and_repeat_by_seed() -> None:
    first, again, other = (UniformLevels(LEVELS)(seed) for seed in (3, 3, 4))
    drawn = [first.next_task() for _ in range(400)]
    assert {task.params["level"] for task in drawn} == set(range(LEVELS))
    assert [again.next_task().params for _ in range(400)] == [task.params for task in drawn]
    assert [other.next_task().params for _ in range(400)] != [task.params for task in drawn]
    assert len({task.task_id for task in drawn}) == len(drawn), "each episode has an id of its own, so none is offline"


def test_a_worker_given_a_task_source_plays_its_levels_without_a_service(ray_cluster: str) -> None:
    torch.manual_seed(0)
    network = ActorCritic(PolicySpec(obs_dim=147, action_dim=7, hidden_sizes=(16,), categorical=True))
    snapshot = ray.put(capture_snapshot(network, RunningNormalizer(147), version=1))
    settings = WorkerSettings(
        "http://127.0.0.1:9",  # nothing listens here: episodes would go offline if the worker asked the service
        "unused",
        4,
        rollout_length=64,
        max_episode_steps=10,
        env_id="MiniGrid-DoorKey-5x5-v0",
        task_source=UniformLevels(3),
    )
    worker = RolloutWorker.remote(settings, 0)  # type: ignore[attr-defined]
    try:
        batch = ray.get(worker.sample.remote(snapshot))
    finally:
        ray.kill(worker)
    assert len(batch.episodes) >= 20
    assert all(episode.task_id is not None for episode in batch.episodes)
    assert {episode.task["level"] for episode in batch.episodes} == {0, 1, 2}
    assert batch.results_waiting == 0 and batch.results_dropped == 0


def episode(level: int, success: bool, score: float) -> EpisodeStats:
    return EpisodeStats(
        task={"level": level}, reward=float(success), success=success, length=10, task_id="t", score=score
    )


def test_syllabus_plr_replays_the_level_with_the_highest_score(ray_cluster: str) -> None:
    actor = SyllabusCurriculum.remote("syllabus-plr", LEVELS, 0)  # type: ignore[attr-defined]
    try:
        # Syllabus replays only once every level has a score (its rho of 1.0)
        ray.get(actor.report.remote([(level, 0.0, 10, False, 0.1 * (level == 7)) for level in range(LEVELS)]))
        distribution = np.array(ray.get(actor.distribution.remote()))
        draws = ray.get(actor.sample.remote(400))
    finally:
        ray.kill(actor)
    assert distribution.argmax() == 7 and distribution.sum() == pytest.approx(1.0)
    # half the draws replay (0.9 of them level 7 at temperature 0.1), half explore uniformly
    assert 0.35 < np.mean(np.array(draws) == 7) < 0.65


def test_syllabus_learning_progress_draws_the_levels_whose_success_moves(ray_cluster: str) -> None:
    actor = SyllabusCurriculum.remote("syllabus-learning-progress", LEVELS, 0, 2 * LEVELS)  # type: ignore[attr-defined]
    try:
        for round_ in range(6):  # levels 0 and 1 go from failing to succeeding; the rest stay put
            results = [(level, 0.0, 10, level < 2 and round_ >= 3, 0.0) for level in range(LEVELS)] * 2
            ray.get(actor.report.remote(results))
        distribution = np.array(ray.get(actor.distribution.remote()))
    finally:
        ray.kill(actor)
    assert set(np.argsort(distribution)[-2:]) == {0, 1}
    assert distribution[:2].min() > 3 * distribution[2:].max()


def test_the_workers_source_draws_and_reports_in_blocks(ray_cluster: str) -> None:
    actor = SyllabusCurriculum.options(name="blocks-test").remote("syllabus-plr", LEVELS, 0)  # type: ignore[attr-defined]
    try:
        source = SyllabusLevels("blocks-test")(0)
        tasks = [source.next_task() for _ in range(BLOCK + 1)]
        for task in tasks:
            source.report(episode(task.params["level"], False, 1.0 if task.params["level"] == 5 else 0.0))
        # A count, not Syllabus's sampler: unpickling that here would import Syllabus's task_sampler, whose
        # import sets numpy's errors to raise for the whole test process (np.seterr(all="raise")).
        scored = ray.get(actor.__ray_call__.remote(lambda self: int((self.sampler.unseen_task_weights == 0).sum())))
    finally:
        ray.kill(actor)
    assert all(0 <= task.params["level"] < LEVELS for task in tasks)
    assert len(source.unsent) == 1, "one block sent, the last result waiting for the next"
    assert scored == len({t.params["level"] for t in tasks[:BLOCK]})


def test_an_unknown_kind_is_refused(ray_cluster: str) -> None:
    actor = SyllabusCurriculum.remote("syllabus-nope", LEVELS, 0)  # type: ignore[attr-defined]
    with pytest.raises(ray.exceptions.RayActorError, match="unknown Syllabus kind"):
        ray.get(actor.sample.remote(1))
