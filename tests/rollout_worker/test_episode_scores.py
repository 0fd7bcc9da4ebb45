"""The two episode scores the rollout workers can send, by their own names: ``positive_value_loss`` (the
mean of max(GAE advantage, 0), robust PLR's) and ``value_l1`` (the mean absolute GAE advantage, the PLR
paper's and Syllabus's example's), against a hand-computed episode; and the trainer setting that picks one."""

from __future__ import annotations

import numpy as np
import pytest

from common.client.teacher_client import Assignment
from common.levels.env import make_level_env
from common.policy.trajectory import EpisodeStats
from learner.core.config import LEVEL_SCORES, PPOConfig
from learner.core.ppo import compute_advantages
from rollout_worker.sampler import EPISODE_SCORES, Sampler, ScoreDiscount, positive_value_loss, value_l1
from tests.rollout_worker.test_level_sampling import joined, level_policy

# Two steps, gamma 0.9, lambda 0.5, terminated: delta_1 = 1 + 0 - 2.0 = -1.0, A_1 = -1.0;
# delta_0 = 0 + 0.9 * 2.0 - 0.5 = 1.3, A_0 = 1.3 + 0.9 * 0.5 * (-1.0) = 0.85.
REWARDS, VALUES = np.array([0.0, 1.0]), np.array([0.5, 2.0])
DISCOUNT = ScoreDiscount(gamma=0.9, gae_lambda=0.5)


def test_positive_value_loss_averages_the_positive_advantages() -> None:
    assert positive_value_loss(REWARDS, VALUES, 0.0, DISCOUNT) == pytest.approx((0.85 + 0.0) / 2)


def test_value_l1_averages_the_absolute_advantages() -> None:
    assert value_l1(REWARDS, VALUES, 0.0, DISCOUNT) == pytest.approx((0.85 + 1.0) / 2)
    # Cut short with V = 1 after the last step: delta_1 = 1 + 0.9 - 2.0 = -0.1, A_0 = 1.3 - 0.045.
    assert value_l1(REWARDS, VALUES, 1.0, DISCOUNT) == pytest.approx((1.255 + 0.1) / 2)


def test_the_trainer_setting_names_exactly_the_scores_the_workers_compute() -> None:
    assert set(LEVEL_SCORES) == set(EPISODE_SCORES)
    assert PPOConfig().level_score == "positive_value_loss", "the default every earlier run used"
    assert PPOConfig().with_overrides({"level_score": "value_l1"}).level_score == "value_l1"
    with pytest.raises(ValueError, match="level_score must be one of positive_value_loss, value_l1"):
        PPOConfig().with_overrides({"level_score": "value-l1"})
    with pytest.raises(ValueError, match="score must be one of"):
        ScoreDiscount(0.9, 0.5, score="max_mc")  # type: ignore[arg-type]


class Levels:
    def __init__(self) -> None:
        self.reported: list[EpisodeStats] = []
        self.count = 0

    def next_task(self) -> Assignment:
        self.count += 1
        return Assignment(f"level:{self.count}", {"level": self.count})

    def report(self, episode: EpisodeStats) -> None:
        self.reported.append(episode)


def test_the_workers_send_the_score_they_are_set_to() -> None:
    discount = ScoreDiscount(gamma=0.97, gae_lambda=0.9, score="value_l1")
    tasks = Levels()
    environments = [make_level_env("MiniGrid-DoorKey-5x5-v0", max_steps=25) for _ in range(2)]
    sampler = Sampler(environments, tasks, seed=1, score_discount=discount)
    batch = joined([sampler.sample(level_policy(1), 10) for _ in range(6)])  # episodes cross batches
    advantages, _ = compute_advantages(batch, discount.gamma, discount.gae_lambda)
    ends = batch.terminated | batch.truncated
    expected = {}
    for env_index in range(2):
        start = 0
        for end in np.flatnonzero(ends[:, env_index]):
            expected[(end, env_index)] = float(np.abs(advantages[start : end + 1, env_index]).mean())
            start = end + 1
    scores = [episode.score for episode in batch.episodes]
    assert len(scores) >= 4
    assert scores == pytest.approx([expected[key] for key in sorted(expected)], rel=1e-5, abs=1e-7)
