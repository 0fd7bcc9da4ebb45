"""PPO on image observations (``PolicySpec.image_shape``): the update trains both heads' encoders on the raw
pixels the workers acted on, with no observation normaliser on either side, and a small CNN policy learns
to read an image."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from reach_env import RecordingTasks

from common.policy.actor_critic import InferencePolicy, PolicySpec
from learner.core.config import PPOConfig
from learner.core.ppo import PPOLearner
from rollout_worker.sampler import Sampler, run_episodes

SHAPE = (8, 8, 1)


class BrightSide(gym.Env[np.ndarray, Any]):
    """A one-step choice on an 8 x 8 grey image of dim noise with a bright 2 x 2 square somewhere in its left or
    right half: choosing that side pays 1. Discrete: action 0 is left, 1 right; a box: the action's sign."""

    def __init__(self, discrete: bool = True) -> None:
        self.observation_space = gym.spaces.Box(0.0, 255.0, (int(np.prod(SHAPE)),), np.float32)
        self.action_space = gym.spaces.Discrete(2) if discrete else gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.right = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.right = bool(self.np_random.integers(2))
        image = self.np_random.integers(0, 40, size=SHAPE).astype(np.float32)
        row, column = self.np_random.integers(0, 7), self.np_random.integers(0, 3) + (4 if self.right else 0)
        image[row : row + 2, column : column + 2] = 255.0
        return image.reshape(-1), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        chose_right = int(action) == 1 if isinstance(self.action_space, gym.spaces.Discrete) else float(action[0]) > 0
        right = chose_right == self.right
        return np.zeros(int(np.prod(SHAPE)), np.float32), float(right), True, False, {"is_success": right}


def spec(**options: Any) -> PolicySpec:
    return PolicySpec(obs_dim=int(np.prod(SHAPE)), hidden_sizes=(16,), image_shape=SHAPE, **options)


@pytest.mark.parametrize(
    ("options", "discrete"),
    [
        ({"action_dim": 1}, False),
        ({"action_dim": 1, "state_dependent_std": True}, False),
        ({"action_dim": 2, "categorical": True}, True),
    ],
    ids=["gaussian", "state-dependent-std", "categorical"],
)
def test_an_update_on_images_trains_both_encoders_on_the_pixels_the_workers_acted_on(options, discrete):
    """The recorded log-probabilities are the numpy policy's; the learner's own on the same steps agree (the
    first minibatch's ratios are 1, so a near-zero learning rate leaves an approximate KL of about 0), which
    they would not if either side scaled or normalised the pixels differently."""
    config = PPOConfig(minibatch_size=64, update_epochs=1, learning_rate=1e-8, anneal_lr=False)
    learner = PPOLearner(spec(**options), config, seed=0)
    with torch.no_grad():  # outputs far from the near-zero start, where any input gives nearly the same
        for parameter in learner.network.parameters():
            parameter.add_(0.1 * torch.randn(parameter.shape, generator=torch.Generator().manual_seed(1)))
    batch = Sampler([BrightSide(discrete) for _ in range(4)], RecordingTasks(), seed=0).sample(
        InferencePolicy(learner.snapshot(), seed=0), 16
    )
    metrics = learner.update([batch])
    assert metrics["approx_kl"] == pytest.approx(0.0, abs=1e-6) and metrics["clip_fraction"] == 0.0
    assert learner.normalizer.count == 0 and learner.version == 1  # images are never normalised

    config = PPOConfig(minibatch_size=32, update_epochs=2, learning_rate=1e-3)
    learner = PPOLearner(spec(**options), config, seed=0)
    convolutions = [learner.network.actor_mean[1], learner.network.critic[1], learner.network.critic[3]]
    before = [convolution.weight.detach().clone() for convolution in convolutions]
    metrics = learner.update([batch])
    assert all(np.isfinite(value) for value in metrics.values())
    for convolution, weight in zip(convolutions, before, strict=True):
        assert not torch.equal(convolution.weight, weight)


def test_a_categorical_cnn_policy_learns_which_side_is_bright():
    config = PPOConfig(rollout_length=64, gamma=0.9, minibatch_size=64, update_epochs=4, learning_rate=3e-3)
    learner = PPOLearner(spec(action_dim=2, categorical=True), config, seed=0)
    sampler = Sampler([BrightSide() for _ in range(4)], RecordingTasks(), seed=0)

    def success() -> float:
        episodes = run_episodes(BrightSide(), InferencePolicy(learner.snapshot()), {}, range(100), deterministic=True)
        return float(np.mean([e.success for e in episodes]))

    untrained = success()
    for iteration in range(10):
        learner.update([sampler.sample(InferencePolicy(learner.snapshot(), seed=iteration), 64)], iteration / 10)
    assert success() >= 0.95 > untrained + 0.3


def test_an_image_learners_state_restores_the_same_policy():
    """What a checkpoint holds: the encoders' weights and the (untouched) normaliser load back as they were."""
    config = PPOConfig(minibatch_size=32, update_epochs=1, learning_rate=1e-2)
    learner = PPOLearner(spec(action_dim=2, categorical=True), config, seed=0)
    batch = Sampler([BrightSide() for _ in range(4)], RecordingTasks(), seed=0).sample(
        InferencePolicy(learner.snapshot(), seed=0), 16
    )
    learner.update([batch])
    restored = PPOLearner(spec(action_dim=2, categorical=True), config, seed=1)
    restored.load_policy_state(learner.state_dict())
    observations = batch.observations.reshape(-1, int(np.prod(SHAPE)))
    for ours, theirs in zip(
        InferencePolicy(learner.snapshot(), seed=2).act(observations),
        InferencePolicy(restored.snapshot(), seed=2).act(observations),
        strict=True,
    ):
        assert np.array_equal(ours, theirs)
