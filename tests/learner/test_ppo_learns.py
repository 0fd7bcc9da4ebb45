import numpy as np
import pytest
from reach_env import ReachTarget, RecordingTasks

from common.policy.actor_critic import InferencePolicy, PolicySpec
from learner.core.config import PPOConfig
from learner.core.ppo import PPOLearner
from rollout_worker.sampler import Sampler, run_episodes

EVAL_SEEDS = range(1000, 1040)


def evaluate(learner: PPOLearner) -> tuple[float, float]:
    episodes = run_episodes(ReachTarget(), InferencePolicy(learner.snapshot()), {}, EVAL_SEEDS)
    return float(np.mean([e.reward for e in episodes])), float(np.mean([e.success for e in episodes]))


@pytest.mark.parametrize("policy_lag", [0, 1], ids=["on-policy", "one-update-lag"])
def test_ppo_learns_to_reach_a_badly_scaled_target_within_a_small_budget(policy_lag):
    """With a lag of one, each batch is sampled with the weights from before the previous update,
    as the asynchronous training loop does."""
    config = PPOConfig(rollout_length=128, gamma=0.99, minibatch_size=128, update_epochs=10, learning_rate=1e-3)
    learner = PPOLearner(PolicySpec(obs_dim=2, action_dim=1, hidden_sizes=(32, 32), init_log_std=0.0), config, seed=1)
    tasks = RecordingTasks()
    sampler = Sampler([ReachTarget() for _ in range(4)], tasks, seed=1)
    untrained_return, untrained_success = evaluate(learner)

    iterations = 25
    behaviour = learner.snapshot()
    for iteration in range(iterations):
        batch = sampler.sample(InferencePolicy(behaviour, seed=iteration), config.rollout_length)
        if policy_lag == 0:
            learner.update([batch], progress=iteration / iterations)
        behaviour = learner.snapshot()  # lagged: taken before the update that this batch feeds
        if policy_lag == 1:
            learner.update([batch], progress=iteration / iterations, max_policy_lag=1)

    trained_return, trained_success = evaluate(learner)
    assert trained_success >= 0.9, (untrained_success, trained_success)
    assert trained_return > untrained_return + 2.0, (untrained_return, trained_return)
    # The normaliser converged on the badly scaled observations it was fed.
    assert np.allclose(learner.normalizer.mean, [300.0, -7.0], atol=10.0)
    assert tasks.reported and len(tasks.reported) <= tasks.handed_out


def test_a_batch_from_an_earlier_policy_is_refused():
    learner = PPOLearner(PolicySpec(obs_dim=2, action_dim=1, hidden_sizes=(8,)), PPOConfig(minibatch_size=32), seed=0)
    sampler = Sampler([ReachTarget()], RecordingTasks(), seed=0)
    batch = sampler.sample(InferencePolicy(learner.snapshot()), 32)
    learner.update([batch])
    with pytest.raises(ValueError, match="on-policy"):
        learner.update([batch])
    learner.update([batch], max_policy_lag=1)  # the asynchronous loop's one update behind
    with pytest.raises(ValueError, match="at most 1 behind"):
        learner.update([batch], max_policy_lag=1)
