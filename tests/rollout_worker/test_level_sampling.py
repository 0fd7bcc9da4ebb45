"""The sampler on a real MiniGrid level family: discrete actions, each episode's score (by default robust PLR's
positive value loss, from the values the policy predicted as it acted) and the score-only episodes' marks.

The score is computed in the worker at each episode's end; here it must equal what the learner's own GAE
(``learner.core.ppo.compute_advantages``) gives for the same steps, episodes that cross batches included."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from common.client.teacher_client import Assignment
from common.levels.env import make_level_env
from common.policy.actor_critic import ActorCritic, InferencePolicy, PolicySpec, capture_snapshot
from common.policy.normalizer import RunningNormalizer
from common.policy.trajectory import EpisodeStats, TrajectoryBatch
from learner.core.ppo import compute_advantages
from rollout_worker.sampler import (
    SCORE_BLOCK,
    Sampler,
    ScoreDiscount,
    discounted_suffix_sums,
    positive_value_loss,
    run_episodes,
)

ENV_ID = "MiniGrid-DoorKey-5x5-v0"
DISCOUNT = ScoreDiscount(gamma=0.97, gae_lambda=0.9)


class Levels:
    """Levels 0, 1, 2, ... in turn; every ``score_only_every``-th task is score-only (0: none)."""

    def __init__(self, score_only_every: int = 0) -> None:
        self.score_only_every = score_only_every
        self.handed_out: list[Assignment] = []
        self.reported: list[EpisodeStats] = []

    def next_task(self) -> Assignment:
        count = len(self.handed_out)
        score_only = self.score_only_every > 0 and count % self.score_only_every == 1
        assignment = Assignment(f"level:{count}", {"level": count}, score_only=score_only)
        self.handed_out.append(assignment)
        return assignment

    def report(self, episode: EpisodeStats) -> None:
        self.reported.append(episode)


def level_policy(seed: int = 0) -> InferencePolicy:
    torch.manual_seed(seed)
    network = ActorCritic(PolicySpec(obs_dim=147, action_dim=7, hidden_sizes=(16,), categorical=True))
    with torch.no_grad():  # values far from zero, so every score is a real one
        for parameter in network.critic.parameters():
            parameter.add_(0.5 * torch.randn_like(parameter))
    return InferencePolicy(capture_snapshot(network, RunningNormalizer(147), version=2), seed=seed)


def envs(count: int, max_steps: int) -> list:
    return [make_level_env(ENV_ID, max_steps=max_steps) for _ in range(count)]


def joined(batches: list[TrajectoryBatch]) -> TrajectoryBatch:
    """Consecutive batches as one (the learner would see the same steps, with each batch's own bootstrap)."""
    arrays = {
        name: np.concatenate([getattr(b, name) for b in batches])
        for name in ("observations", "actions", "log_probs", "values", "rewards", "terminated", "truncated")
    }
    return TrajectoryBatch(
        **arrays,
        final_values=np.concatenate([b.final_values for b in batches]),
        last_values=batches[-1].last_values,
        policy_version=batches[-1].policy_version,
        episodes=[e for b in batches for e in b.episodes],
    )


def test_discrete_actions_step_the_levels_the_tasks_name():
    tasks = Levels()
    sampler = Sampler(envs(2, max_steps=30), tasks, seed=0)
    batch = sampler.sample(level_policy(), 70)
    assert batch.actions.shape == (70, 2, 1) and batch.observations.shape == (70, 2, 147)
    assert set(np.unique(batch.actions)) <= set(range(7)) and len(np.unique(batch.actions)) > 3
    assert batch.score_only is None and all(e.score is None for e in batch.episodes)  # no discount: no scores
    # Each episode ran on the level its task named: its first observation is that level's.
    fresh = make_level_env(ENV_ID)
    current, following = list(tasks.handed_out[:2]), iter(tasks.handed_out[2:])
    starts = np.ones(2, dtype=bool)
    checked = 0
    for step in range(len(batch.rewards)):
        for env_index in np.flatnonzero(starts):
            first, _ = fresh.reset(options={"task": current[env_index].params})
            assert np.array_equal(batch.observations[step, env_index], first)
            checked += 1
        starts = batch.truncated[step] | batch.terminated[step]
        for env_index in np.flatnonzero(starts):
            current[env_index] = next(following)
    assert checked >= 4


def test_each_episode_carries_the_learners_positive_value_loss_across_batches():
    tasks = Levels()
    sampler = Sampler(envs(3, max_steps=25), tasks, seed=1, score_discount=DISCOUNT)
    policy = level_policy(1)
    batches = [sampler.sample(policy, 10) for _ in range(6)]  # 25-step episodes cross the 10-step batches
    batch = joined(batches)
    advantages, _ = compute_advantages(batch, DISCOUNT.gamma, DISCOUNT.gae_lambda)

    ends = batch.terminated | batch.truncated
    expected = {}
    for env_index in range(3):
        start = 0
        for end in np.flatnonzero(ends[:, env_index]):
            expected[(env_index, end)] = float(np.maximum(advantages[start : end + 1, env_index], 0.0).mean())
            start = end + 1
    in_order = [expected[key] for key in sorted(expected, key=lambda key: (key[1], key[0]))]
    assert len(in_order) >= 6
    scores = [episode.score for episode in batch.episodes]
    assert scores == pytest.approx(in_order, rel=1e-5, abs=1e-7)
    assert all(score > 0 for score in scores)
    assert tasks.reported == batch.episodes


def test_a_score_only_episodes_steps_are_marked_and_it_is_still_reported():
    tasks = Levels(score_only_every=2)
    sampler = Sampler(envs(2, max_steps=12), tasks, seed=2, score_discount=DISCOUNT)
    batches = [sampler.sample(level_policy(2), 9) for _ in range(4)]
    batch = joined(batches)
    marks = np.concatenate([b.score_only if b.score_only is not None else np.zeros((9, 2), bool) for b in batches])

    # Replay which task each step belonged to: the first two tasks start the environments, the rest follow in order.
    current, following = list(tasks.handed_out[:2]), iter(tasks.handed_out[2:])
    expected = np.zeros_like(marks)
    for step in range(len(marks)):
        expected[step] = [assignment.score_only for assignment in current]
        for env_index in np.flatnonzero(batch.truncated[step] | batch.terminated[step]):
            current[env_index] = next(following)
    assert marks.any() and not marks.all()
    assert np.array_equal(marks, expected)
    reported = {episode.task_id: episode.score_only for episode in tasks.reported}
    assert reported == {a.task_id: a.score_only for a in tasks.handed_out if a.task_id in reported}
    assert any(reported.values()) and all(episode.score is not None for episode in tasks.reported)


@pytest.mark.parametrize("length", [1, 7, SCORE_BLOCK, SCORE_BLOCK + 1, 3 * SCORE_BLOCK + 17])
@pytest.mark.parametrize("discount", [0.0, 0.5, 0.99 * 0.95, 1.0])
def test_discounted_suffix_sums_match_the_step_by_step_recursion(length, discount):
    values = np.random.default_rng(length).normal(size=length)
    expected, running = np.zeros(length), 0.0
    for step in reversed(range(length)):
        running = values[step] + discount * running
        expected[step] = running
    assert discounted_suffix_sums(values, discount) == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_a_terminated_episode_bootstraps_from_zero_and_a_truncated_one_from_its_last_value():
    rewards, values = np.array([0.0, 0.0, 1.0]), np.array([0.2, 0.5, 0.1])
    discount = ScoreDiscount(gamma=1.0, gae_lambda=1.0)  # advantages are returns minus values
    assert positive_value_loss(rewards, values, 0.0, discount) == pytest.approx((0.8 + 0.5 + 0.9) / 3)
    assert positive_value_loss(rewards, values, 2.0, discount) == pytest.approx((2.8 + 2.5 + 2.9) / 3)
    assert positive_value_loss(np.zeros(3), np.ones(3), 0.0, discount) == 0.0  # every advantage negative


def test_held_out_levels_play_with_sampled_actions():
    env = make_level_env(ENV_ID, max_steps=15)
    episodes = run_episodes(env, level_policy(3), {}, seeds=[1_000_000, 1_000_001], deterministic=False)
    assert [e.length for e in episodes] == [15, 15] and not any(e.success for e in episodes)
