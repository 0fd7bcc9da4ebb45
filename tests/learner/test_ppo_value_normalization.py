"""``PPOConfig.normalize_values``: the critic learns standardised returns, while the values the workers compute
from its snapshot, which GAE and the episodes' scores read, stay in return units; moving statistics leave those
values where they were (PopArt), and the statistics travel with the learner's state."""

import numpy as np
import pytest
import torch

from common.policy.actor_critic import InferencePolicy, PolicySpec
from common.policy.trajectory import TrajectoryBatch
from learner.core.config import PPOConfig
from learner.core.ppo import PPOLearner

SPEC = PolicySpec(obs_dim=2, action_dim=1, hidden_sizes=(16,))
STEPS, ENVS = 16, 16
CONFIG = PPOConfig(learning_rate=3e-3, anneal_lr=False, minibatch_size=64, update_epochs=10, normalize_values=True)


def return_batch(learner: PPOLearner, seed: int, offset: float, scale: float) -> TrajectoryBatch:
    """One-step episodes whose return is ``offset + scale x`` the observation's first entry, with the values the
    workers would have computed from the learner's current snapshot."""
    rng = np.random.default_rng(seed)
    shape = (STEPS, ENVS)
    observations = rng.normal(size=(*shape, SPEC.obs_dim)).astype(np.float32)
    values = InferencePolicy(learner.snapshot()).value(observations.reshape(-1, SPEC.obs_dim)).reshape(shape)
    return TrajectoryBatch(
        observations=observations,
        actions=rng.uniform(-1, 1, size=(*shape, 1)).astype(np.float32),
        log_probs=np.full(shape, -1.0, np.float32),
        values=values,
        rewards=(offset + scale * observations[..., 0]).astype(np.float32),
        terminated=np.ones(shape, bool),
        truncated=np.zeros(shape, bool),
        final_values=np.zeros(shape, np.float32),
        last_values=np.zeros(ENVS, np.float32),
        policy_version=learner.version,
    )


def probe() -> np.ndarray:
    return np.random.default_rng(99).normal(size=(256, SPEC.obs_dim)).astype(np.float32)


@pytest.mark.parametrize("normalize_values", [True, False], ids=["normalised", "raw"])
def test_the_critic_learns_standardised_returns_and_the_workers_values_are_in_return_units(normalize_values):
    """Returns of 1000 +- 100: the standardised critic fits them in a few updates and its snapshot's values, the
    workers', are on their scale; a raw critic's Adam steps of ~3e-3 cannot even reach their mean."""
    learner = PPOLearner(SPEC, PPOConfig(**{**vars(CONFIG), "normalize_values": normalize_values}), seed=0)
    for update in range(6):
        learner.update([return_batch(learner, seed=update, offset=1000.0, scale=100.0)])

    observations = probe()
    values = InferencePolicy(learner.snapshot()).value(observations)
    returns = 1000.0 + 100.0 * observations[:, 0]
    if not normalize_values:
        assert np.abs(values - returns).mean() > 900.0
        return
    assert np.abs(values - returns).mean() < 10.0
    mean, std = learner.value_scale() or (0.0, 0.0)
    assert mean == pytest.approx(1000.0, abs=10.0) and std == pytest.approx(100.0, rel=0.1)
    inputs = torch.from_numpy(learner.normalizer.normalize(observations))
    outputs = learner.network.value(inputs).detach().numpy()  # what the critic itself learns: standardised
    assert abs(outputs.mean()) < 0.2 and outputs.std() == pytest.approx(1.0, abs=0.2)
    assert values == pytest.approx(mean + std * outputs, rel=1e-5)


def test_statistics_that_move_leave_the_workers_values_where_they_were():
    """With a learning rate too small to move the network, a batch of returns near 500 moves the statistics
    far; the critic's last layer is rescaled with them, so its values stay put (after the first batch, which
    sets the statistics outright). Both batches hold the same observations, which leave the observation
    normaliser as it was."""
    config = PPOConfig(**{**vars(CONFIG), "learning_rate": 1e-12})
    learner = PPOLearner(SPEC, config, seed=0)
    learner.update([return_batch(learner, seed=0, offset=0.0, scale=1.0)])
    before, scale_before = InferencePolicy(learner.snapshot()).value(probe()), learner.value_scale()
    learner.update([return_batch(learner, seed=0, offset=500.0, scale=50.0)])
    after, scale_after = InferencePolicy(learner.snapshot()).value(probe()), learner.value_scale()

    assert scale_before is not None and scale_after is not None
    assert scale_after[0] > scale_before[0] + 200.0 and scale_after[1] > 10.0 * scale_before[1]
    assert after == pytest.approx(before, abs=1e-3)


def test_the_value_statistics_travel_with_the_learners_state():
    learner = PPOLearner(SPEC, CONFIG, seed=0)
    learner.update([return_batch(learner, seed=0, offset=40.0, scale=5.0)])
    state = learner.state_dict()
    assert "value_statistics" in state and "value_statistics" not in PPOLearner(SPEC, PPOConfig(), 0).state_dict()

    restored = PPOLearner(SPEC, CONFIG, seed=1)
    restored.load_state_dict(state)
    assert restored.value_scale() == learner.value_scale()
    expected = InferencePolicy(learner.snapshot()).value(probe())
    assert np.array_equal(InferencePolicy(restored.snapshot()).value(probe()), expected)
    with pytest.raises(ValueError, match="critic learned standardised values: it needs normalize_values"):
        PPOLearner(SPEC, PPOConfig(), seed=0).load_state_dict(state)
