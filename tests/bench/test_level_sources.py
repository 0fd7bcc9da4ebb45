"""The level side-by-side's stand-ins for the teacher service: uniform levels with no service at all, and
Syllabus 0.7's curricula in a Ray actor with the settings of Syllabus's own procgen example, each fed through
a real worker or real reports. A test here fails if an arm departs from what its authors ship: Syllabus's PLR
drawn through anything but its own ``TaskSampler.sample()`` with the fixed schedule, its learning progress
asked before its first update, or its learnability's evaluation not played, score-only, before it draws."""

from __future__ import annotations

import numpy as np
import pytest
import ray
import torch

from bench.level_sources import (
    BLOCK,
    EVALUATION_EPISODES_PER_LEVEL,
    SyllabusCurriculum,
    SyllabusLevels,
    UniformLevels,
)
from common.policy.actor_critic import ActorCritic, PolicySpec, capture_snapshot
from common.policy.normalizer import RunningNormalizer
from common.policy.trajectory import EpisodeStats
from rollout_worker.actor import RolloutWorker, WorkerSettings

LEVELS = 12
BATCH = 4
"""A run's batch size as the actor is told it: the example's intervals are 25 batches, 100 steps here."""


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


def result(level: int, success: bool = False, score: float | None = 0.0, length: int = 10, evaluation: int = 0):
    return (level, float(success), length, success, score, evaluation)


def inside(actor, read):
    """A value read off the actor's Syllabus objects in its own process: unpickling them here would import
    Syllabus's task_sampler, which sets numpy's errors to raise for the whole test process."""
    return ray.get(actor.__ray_call__.remote(lambda self: read(self.curriculum)))


def test_syllabus_plr_is_its_examples_task_sampler_sweeping_then_always_replaying(ray_cluster: str) -> None:
    actor = SyllabusCurriculum.remote("syllabus-plr", LEVELS, 0, BATCH)  # type: ignore[attr-defined]
    try:
        settings = inside(
            actor,
            lambda plr: {
                name: getattr(plr.sampler, name)
                for name in ("strategy", "replay_schedule", "score_transform", "temperature", "staleness_coef", "rho")
            },
        )
        # The sweep: each draw an unseen level, while any is left.
        swept = []
        for _ in range(LEVELS):
            (level, evaluation), *_ = ray.get(actor.sample.remote(1))
            swept.append(level)
            assert evaluation == 0
            ray.get(actor.report.remote([result(level, score=0.1 * (level == 7))]))
        assert ray.get(actor.status.remote()) == {"seen_share": 1.0}
        # After it, its own TaskSampler.sample(): no evaluator is asked for (it has none), every draw replays.
        replays = [level for level, _ in ray.get(actor.sample.remote(1000))]
        drawn = inside(actor, lambda plr: plr.sampler.running_sample_count)
    finally:
        ray.kill(actor)
    assert settings == {
        "strategy": "value_l1",
        "replay_schedule": "fixed",
        "score_transform": "rank",
        "temperature": 0.1,
        "staleness_coef": 0.1,
        "rho": 1.0,
    }
    assert sorted(swept) == list(range(LEVELS)), "every level once before any replay"
    assert drawn == LEVELS + 1000, "each draw is one TaskSampler.sample()"
    # Rank at temperature 0.1 puts 0.999 of the score weight on level 7, staleness 0.1 of the whole: about 0.9.
    # Half the draws uniform (a hybrid, or the proportionate schedule's 0.5) would give under 0.5.
    assert np.mean(np.array(replays) == 7) > 0.8


def test_syllabus_plr_refuses_an_episode_without_its_score(ray_cluster: str) -> None:
    actor = SyllabusCurriculum.remote("syllabus-plr", LEVELS, 0, BATCH)  # type: ignore[attr-defined]
    try:
        with pytest.raises(ray.exceptions.RayTaskError, match="needs each episode's score"):
            ray.get(actor.report.remote([result(3, score=None)]))
    finally:
        ray.kill(actor)


def test_syllabus_learning_progress_is_asked_only_after_its_first_update(ray_cluster: str) -> None:
    batch = 2 * LEVELS
    actor = SyllabusCurriculum.remote("syllabus-learning-progress", LEVELS, 0, batch)  # type: ignore[attr-defined]
    try:
        settings = inside(
            actor,
            lambda lp: (
                (lp.curriculum.eval_interval_steps, lp.curriculum.ema_alpha, lp.curriculum.p_theta)
                + (lp.curriculum.normalize_success, lp.curriculum.uniform_prob)
            ),
        )
        early = [level for level, _ in ray.get(actor.sample.remote(500))]
        asked_early = inside(actor, lambda lp: lp.curriculum.task_rates is not None)
        # One update a round: 2 results per level of 26 steps, 624 steps, past the interval of 25 batches (600).
        updated = []
        for round_ in range(6):  # levels 0 and 1 go from failing to succeeding; the rest stay put
            results = [result(level, level < 2 and round_ >= 3, length=26) for level in range(LEVELS)] * 2
            ray.get(actor.report.remote(results))
            updated.append(ray.get(actor.status.remote())["updated"])
        distribution = np.array(ray.get(actor.distribution.remote()))
    finally:
        ray.kill(actor)
    assert settings == (25 * batch, 0.1, 0.1, False, 0.25)
    assert not asked_early, "drawing before the first update did not touch Syllabus's averages"
    assert set(early) == set(range(LEVELS)), "uniform draws until then"
    assert updated == [True] * 6
    assert set(np.argsort(distribution)[-2:]) == {0, 1}
    assert distribution[:2].min() > 3 * distribution[2:].max()


def test_syllabus_learnability_plays_its_evaluations_on_the_workers_before_it_draws(ray_cluster: str) -> None:
    levels = 20
    episodes = EVALUATION_EPISODES_PER_LEVEL * levels
    actor = SyllabusCurriculum.remote("syllabus-learnability", levels, 0, BATCH)  # type: ignore[attr-defined]
    try:
        settings = inside(
            actor,
            lambda lb: (
                (lb.curriculum.k, lb.curriculum.learnable_prob, lb.curriculum.sampling)
                + (lb.curriculum.eval_interval_steps, lb.curriculum.eval_eps, lb.curriculum.continuous_progress)
                + (lb.curriculum.normalize_success,)
            ),
        )
        # Its first distribution asks its evaluator: every task is then one of the evaluation's, levels in turn.
        first = ray.get(actor.sample.remote(episodes + 5))
        training_meanwhile = [result(4, True, length=10)] * 3  # from before: held until the evaluation is over
        ray.get(actor.report.remote(training_meanwhile))
        fed_during = inside(actor, lambda lb: lb.curriculum.completed_episodes)
        # Levels 3 and 5 are solved in every other round of the levels (learnability 0.25), the rest never.
        evaluation = [
            result(level, level in (3, 5) and (index // levels) % 2 == 0, evaluation=1)
            for index, (level, _) in enumerate(first[:episodes])
        ]
        ray.get(actor.report.remote(evaluation[:-1]))
        still = ray.get(actor.status.remote())
        ray.get(actor.report.remote(evaluation[-1:] + [result(0, evaluation=1)]))  # the count, then one too many
        after = ray.get(actor.status.remote())
        fed_after = inside(actor, lambda lb: lb.curriculum.completed_episodes)
        distribution = np.array(ray.get(actor.distribution.remote()))
        training = ray.get(actor.sample.remote(200))
        # Past 100 training steps (the interval, 25 batches of 4; 30 came in meanwhile), the second evaluation starts.
        ray.get(actor.report.remote([result(level, length=10) for level, _ in training[:11]]))
        second = ray.get(actor.sample.remote(3))
    finally:
        ray.kill(actor)
    assert settings == (10, 0.5, "topk", 25 * BATCH, episodes, True, False)
    assert [task for task in first[:levels]] == [(level, 1) for level in range(levels)]
    assert all(evaluation == 1 for _, evaluation in first)
    assert fed_during == 0, "training results wait while an evaluation runs"
    assert still["evaluating"] and still["evaluation_episodes"] == episodes - 1
    assert not after["evaluating"] and after["evaluation_episodes"] == episodes
    assert after["evaluation_episodes_dropped"] == 1
    assert fed_after == len(training_meanwhile)
    top = 0.5 / 10 + 0.5 / levels  # half the draws among the top 10 by learnability, half uniform
    assert distribution[[3, 5]] == pytest.approx([top, top]) and distribution.max() == pytest.approx(top)
    assert all(evaluation == 0 for _, evaluation in training)
    assert second == [((episodes + 5 + k) % levels, 2) for k in range(3)], "the evaluator's round goes on"


def test_the_workers_source_draws_and_reports_in_blocks_and_marks_evaluations_score_only(ray_cluster: str) -> None:
    actor = SyllabusCurriculum.options(name="blocks-test").remote("syllabus-plr", LEVELS, 0, BATCH)  # type: ignore[attr-defined]
    evaluating = SyllabusCurriculum.options(name="evaluating-test").remote("syllabus-learnability", LEVELS, 0, BATCH)  # type: ignore[attr-defined]
    try:
        source = SyllabusLevels("blocks-test")(0)
        tasks = [source.next_task() for _ in range(BLOCK + 1)]
        for task in tasks:
            score = 1.0 if task.params["level"] == 5 else 0.0
            source.report(EpisodeStats(task=task.params, reward=0.0, success=False, length=10, task_id=task.task_id,
                                       score=score))  # fmt: skip
        scored = inside(actor, lambda plr: int((plr.sampler.unseen_task_weights == 0).sum()))
        evaluation_tasks = [SyllabusLevels("evaluating-test")(1).next_task() for _ in range(2)]
    finally:
        ray.kill(actor)
        ray.kill(evaluating)
    assert all(0 <= task.params["level"] < LEVELS and not task.score_only for task in tasks)
    assert len(source.unsent) == 1, "one block sent, the last result waiting for the next"
    assert scored == len({t.params["level"] for t in tasks[:BLOCK]})
    assert all(task.score_only for task in evaluation_tasks), "learnability's evaluation episodes are not trained on"


def test_an_unknown_kind_is_refused(ray_cluster: str) -> None:
    actor = SyllabusCurriculum.remote("syllabus-nope", LEVELS, 0, BATCH)  # type: ignore[attr-defined]
    with pytest.raises(ray.exceptions.RayActorError, match="unknown Syllabus kind"):
        ray.get(actor.sample.remote(1))
