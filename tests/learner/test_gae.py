"""GAE over several environments at once, each column with its own episode ends, against a reference
written the other way round: a forward sum of discounted TD errors per step, not the backward recursion."""

import numpy as np
import pytest

from common.policy.trajectory import TrajectoryBatch
from learner.core.ppo import compute_advantages

GAMMA, LAMBDA = 0.9, 0.8
STEPS, ENVS = 6, 4

# Episode ends per column (step index: what happened after that step's action).
TERMINATED = {1: [2], 2: [5], 3: [3]}
TRUNCATED = {1: [5], 2: [1], 3: [0, 3]}
# V(final observation) where an episode was truncated.
FINAL_VALUES = {(5, 1): 7.0, (1, 2): 2.5, (0, 3): -1.5, (3, 3): 4.0}


def batch(last_values: list[float]) -> TrajectoryBatch:
    """Column 0 never ends; column 1 terminates mid-batch and is truncated on the batch's last step;
    column 2 is truncated mid-batch and terminates on the last step; column 3 is truncated on its
    first step, then terminated and truncated at once (termination wins: nothing to bootstrap)."""
    rng = np.random.default_rng(7)
    shape = (STEPS, ENVS)
    terminated, truncated = np.zeros(shape, bool), np.zeros(shape, bool)
    final_values = np.zeros(shape, np.float32)
    for env, steps in TERMINATED.items():
        terminated[steps, env] = True
    for env, steps in TRUNCATED.items():
        truncated[steps, env] = True
    for (step, env), value in FINAL_VALUES.items():
        final_values[step, env] = value
    return TrajectoryBatch(
        observations=np.zeros((*shape, 1), np.float32),
        actions=np.zeros((*shape, 1), np.float32),
        log_probs=np.zeros(shape, np.float32),
        values=rng.normal(size=shape).astype(np.float32),
        rewards=rng.normal(size=shape).astype(np.float32),
        terminated=terminated,
        truncated=truncated,
        final_values=final_values,
        last_values=np.asarray(last_values, np.float32),
        policy_version=0,
    )


def reference_advantages(batch: TrajectoryBatch, gamma: float, lam: float) -> np.ndarray:
    """A_t = sum over k of (gamma * lam)^k * delta_(t+k), up to and including the step that ends the episode."""
    advantages = np.zeros(batch.rewards.shape)
    for env in range(ENVS):
        for start in range(STEPS):
            total, weight = 0.0, 1.0
            for step in range(start, STEPS):
                if batch.terminated[step, env]:
                    next_value = 0.0
                elif batch.truncated[step, env]:
                    next_value = float(batch.final_values[step, env])
                elif step == STEPS - 1:
                    next_value = float(batch.last_values[env])
                else:
                    next_value = float(batch.values[step + 1, env])
                delta = float(batch.rewards[step, env]) + gamma * next_value - float(batch.values[step, env])
                total += weight * delta
                if batch.terminated[step, env] or batch.truncated[step, env]:
                    break
                weight *= gamma * lam
            advantages[start, env] = total
    return advantages


def test_advantages_of_every_column_match_the_forward_sum():
    trajectories = batch(last_values=[3.0, -3.0, 6.0, 0.5])
    advantages, returns = compute_advantages(trajectories, GAMMA, LAMBDA)
    assert advantages.shape == returns.shape == (STEPS, ENVS)
    # Float32 rewards and values enter each TD error: agreement to float32 precision.
    np.testing.assert_allclose(advantages, reference_advantages(trajectories, GAMMA, LAMBDA), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(returns, advantages + trajectories.values, rtol=1e-12)


def test_the_last_step_bootstraps_from_how_its_episode_ended():
    trajectories = batch(last_values=[3.0, -3.0, 6.0, 0.5])
    advantages, _ = compute_advantages(trajectories, GAMMA, LAMBDA)
    last, r, v = STEPS - 1, trajectories.rewards.astype(np.float64), trajectories.values.astype(np.float64)
    # Column 0 goes on: the value of the observation after the batch.
    assert advantages[last, 0] == pytest.approx(r[last, 0] + GAMMA * 3.0 - v[last, 0])
    # Column 1 was truncated: the value of its final observation, not of the next episode's first (-3.0).
    assert advantages[last, 1] == pytest.approx(r[last, 1] + GAMMA * 7.0 - v[last, 1])
    # Column 2 terminated: nothing.
    assert advantages[last, 2] == pytest.approx(r[last, 2] - v[last, 2])
    # No episode ends on the step before in any column: it chains into the last step.
    for env in range(ENVS):
        delta = r[last - 1, env] + GAMMA * v[last, env] - v[last - 1, env]
        assert advantages[last - 1, env] == pytest.approx(delta + GAMMA * LAMBDA * advantages[last, env])


def test_only_a_column_still_running_at_the_end_of_the_batch_reads_the_value_after_it():
    first, _ = compute_advantages(batch(last_values=[3.0, -3.0, 6.0, 0.5]), GAMMA, LAMBDA)
    second, _ = compute_advantages(batch(last_values=[-2.0, 40.0, -40.0, 1.5]), GAMMA, LAMBDA)
    # Columns 1 and 2 ended on the last step: their next observation belongs to a new episode.
    np.testing.assert_array_equal(first[:, 1:3], second[:, 1:3])
    # Columns 0 and 3 run on: every step of their open episode moves, by (gamma * lambda)^k * gamma * change.
    for env, change, episode_start in ((0, -5.0, 0), (3, 1.0, 4)):
        for step in range(episode_start, STEPS):
            k = STEPS - 1 - step
            assert second[step, env] - first[step, env] == pytest.approx((GAMMA * LAMBDA) ** k * GAMMA * change)
        assert np.array_equal(first[:episode_start, env], second[:episode_start, env])
