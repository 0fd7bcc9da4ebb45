import numpy as np
import pytest

from common.policy.trajectory import TrajectoryBatch
from learner.core.ppo import compute_advantages


def make_batch(rewards, values, terminated=None, truncated=None, final_values=None, last_values=None):
    rewards = np.asarray(rewards, dtype=np.float32).reshape(-1, 1)
    shape = rewards.shape
    return TrajectoryBatch(
        observations=np.zeros((*shape, 1), np.float32),
        actions=np.zeros((*shape, 1), np.float32),
        log_probs=np.zeros(shape, np.float32),
        values=np.asarray(values, np.float32).reshape(shape),
        rewards=rewards,
        terminated=np.asarray(terminated or [False] * shape[0]).reshape(shape),
        truncated=np.asarray(truncated or [False] * shape[0]).reshape(shape),
        final_values=np.asarray(final_values or [0.0] * shape[0], np.float32).reshape(shape),
        last_values=np.asarray([last_values or 0.0], np.float32),
        policy_version=0,
    )


def test_lambda_one_gives_discounted_return_to_go_minus_value():
    gamma, rewards, values = 0.9, [1.0, 2.0, 3.0], [0.5, -1.0, 2.0]
    advantages, returns = compute_advantages(make_batch(rewards, values, last_values=4.0), gamma, 1.0)
    expected_returns = [sum(gamma**k * r for k, r in enumerate(rewards[t:])) + gamma ** (3 - t) * 4.0 for t in range(3)]
    assert returns[:, 0] == pytest.approx(expected_returns, rel=1e-6)
    assert advantages[:, 0] == pytest.approx(np.array(expected_returns) - values, rel=1e-6)


def test_terminal_step_bootstraps_from_zero_and_truncated_step_from_its_final_value():
    gamma, lam = 0.9, 0.8
    rewards, values = [1.0, 1.0, 1.0], [0.2, 0.3, 0.4]
    terminated = compute_advantages(
        make_batch(rewards, values, terminated=[False, True, False], last_values=5.0), gamma, lam
    )[0]
    truncated = compute_advantages(
        make_batch(rewards, values, truncated=[False, True, False], final_values=[0.0, 7.0, 0.0], last_values=5.0),
        gamma,
        lam,
    )[0]
    assert terminated[1, 0] == pytest.approx(1.0 - 0.3)
    assert truncated[1, 0] == pytest.approx(1.0 + gamma * 7.0 - 0.3)
    # The step after the episode end starts a fresh chain in both cases.
    assert terminated[2, 0] == truncated[2, 0] == pytest.approx(1.0 + gamma * 5.0 - 0.4)
    # The step before it chains into the end step, never past it.
    for advantages in (terminated, truncated):
        assert advantages[0, 0] == pytest.approx(1.0 + gamma * 0.3 - 0.2 + gamma * lam * advantages[1, 0])
