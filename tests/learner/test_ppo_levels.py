"""PPO with a categorical head and robust PLR's score-only episodes: the update leaves a score-only
episode's steps out entirely (whatever they hold changes nothing), and a categorical policy learns."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import gymnasium as gym
import numpy as np
from reach_env import RecordingTasks

from common.levels.env import make_level_env
from common.policy.actor_critic import InferencePolicy, PolicySpec
from learner.core.config import PPOConfig
from learner.core.ppo import PPOLearner
from rollout_worker.sampler import Sampler, run_episodes

CONFIG = PPOConfig(
    rollout_length=64, gamma=0.99, gae_lambda=0.95, minibatch_size=64, update_epochs=2, entropy_coef=0.01
)
LEVEL_SPEC = PolicySpec(obs_dim=147, action_dim=7, hidden_sizes=(32, 32), categorical=True)


def level_batch():
    """A real MiniGrid batch of three environments, sampled with an untrained categorical policy."""
    learner = PPOLearner(LEVEL_SPEC, CONFIG, seed=0)
    sampler = Sampler([make_level_env("MiniGrid-DoorKey-5x5-v0", max_steps=20) for _ in range(3)], RecordingTasks(), 0)
    return sampler.sample(InferencePolicy(learner.snapshot(), seed=0), CONFIG.rollout_length)


def updated(batch) -> tuple[PPOLearner, dict[str, float]]:
    learner = PPOLearner(LEVEL_SPEC, CONFIG, seed=0)
    metrics = learner.update([batch])
    return learner, metrics


def weights(learner: PPOLearner) -> list[np.ndarray]:
    return [parameter.detach().numpy().copy() for parameter in learner.network.parameters()]


def test_a_score_only_episodes_steps_change_nothing_in_the_update():
    batch = level_batch()
    marks = np.zeros_like(batch.terminated)
    marks[:, 1] = True  # every step of the second environment: its episodes were for scoring only
    marked = replace(batch, score_only=marks)
    garbage = {
        name: getattr(batch, name).copy()
        for name in ("observations", "actions", "log_probs", "values", "rewards", "final_values")
    }
    rng = np.random.default_rng(1)
    for name, array in garbage.items():
        array[:, 1] = (
            rng.integers(0, 7, size=array[:, 1].shape) if name == "actions" else rng.normal(50, 9, array[:, 1].shape)
        )
    scrambled = replace(marked, **garbage)

    reference, reference_metrics = updated(marked)
    other, other_metrics = updated(scrambled)
    for ours, theirs in zip(weights(reference), weights(other), strict=True):
        assert np.array_equal(ours, theirs)
    assert np.array_equal(reference.normalizer.mean, other.normalizer.mean)
    assert reference.normalizer.count == 2 * CONFIG.rollout_length  # the normaliser saw the trained steps only
    assert reference_metrics == other_metrics

    # Without the marks, the same scrambled steps do change the update: the check above can fail.
    unmarked, _ = updated(replace(scrambled, score_only=None))
    assert not all(np.array_equal(a, b) for a, b in zip(weights(reference), weights(unmarked), strict=True))


def test_a_batch_of_score_only_steps_leaves_the_policy_as_it_was():
    batch = level_batch()
    learner = PPOLearner(LEVEL_SPEC, CONFIG, seed=0)
    before = weights(learner)
    metrics = learner.update([replace(batch, score_only=np.ones_like(batch.terminated))])
    assert all(np.array_equal(a, b) for a, b in zip(before, weights(learner), strict=True))
    assert np.isnan(metrics["policy_loss"]) and learner.normalizer.count == 0 and learner.version == 0
    assert "action_std" not in learner.update([batch])  # a categorical policy has no std to report


class PickTheSign(gym.Env[np.ndarray, np.int64]):
    """A one-step choice among three actions: the observation's sign says which of the first two pays 1."""

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
        self.action_space = gym.spaces.Discrete(3)
        self.sign = 1.0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.sign = float(self.np_random.choice([-1.0, 1.0]))
        return np.array([self.sign * 5.0 + 20.0, 3.0], dtype=np.float32), {}

    def step(self, action: np.int64) -> tuple[np.ndarray, float, bool, bool, dict]:
        right = int(action) == (0 if self.sign > 0 else 1)
        return np.zeros(2, dtype=np.float32), float(right), True, False, {"is_success": right}


def test_a_categorical_policy_learns_a_choice():
    config = PPOConfig(rollout_length=64, gamma=0.9, minibatch_size=64, update_epochs=4, learning_rate=3e-3)
    learner = PPOLearner(PolicySpec(obs_dim=2, action_dim=3, hidden_sizes=(16,), categorical=True), config, seed=0)
    sampler = Sampler([PickTheSign() for _ in range(4)], RecordingTasks(), seed=0)

    def success() -> float:
        episodes = run_episodes(PickTheSign(), InferencePolicy(learner.snapshot()), {}, range(100), deterministic=True)
        return float(np.mean([e.success for e in episodes]))

    untrained = success()
    for iteration in range(30):
        learner.update([sampler.sample(InferencePolicy(learner.snapshot(), seed=iteration), 64)], iteration / 30)
    assert success() >= 0.95 > untrained + 0.3
