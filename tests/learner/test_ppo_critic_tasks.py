"""``PPOConfig.critic_task_inputs``: the learner's critic reads each step's task from the batch, learns values
that only the task explains, and hands the workers a snapshot whose critic computes them too."""

import dataclasses

import numpy as np
import pytest

from common.policy.actor_critic import InferencePolicy, PolicySpec
from common.policy.trajectory import TrajectoryBatch
from learner.core.config import PPOConfig
from learner.core.ppo import PPOLearner

STEPS, ENVS, OBS_DIM, TASK_DIM = 16, 16, 2, 2
SCORE_ONLY_ROWS = 4
"""The first steps of every environment are score-only: the update must leave their tasks out with them."""
CONFIG = PPOConfig(learning_rate=3e-3, anneal_lr=False, minibatch_size=64, update_epochs=10)


def task_batch(learner: PPOLearner, seed: int) -> tuple[TrajectoryBatch, np.ndarray]:
    """One-step episodes on noise observations whose return is 2 x the task's first parameter - 1, except on the
    score-only steps, whose returns go the other way; and the trained steps' returns."""
    rng = np.random.default_rng(seed)
    shape = (STEPS, ENVS)
    tasks = rng.uniform(0.0, 1.0, size=(*shape, TASK_DIM)).astype(np.float32)
    rewards = (2.0 * tasks[..., 0] - 1.0).astype(np.float32)
    rewards[:SCORE_ONLY_ROWS] *= -1.0
    score_only = np.zeros(shape, bool)
    score_only[:SCORE_ONLY_ROWS] = True
    batch = TrajectoryBatch(
        observations=rng.normal(size=(*shape, OBS_DIM)).astype(np.float32),
        actions=rng.uniform(-1, 1, size=(*shape, 1)).astype(np.float32),
        log_probs=np.full(shape, -1.0, np.float32),
        values=np.zeros(shape, np.float32),
        rewards=rewards,
        terminated=np.ones(shape, bool),
        truncated=np.zeros(shape, bool),
        final_values=np.zeros(shape, np.float32),
        last_values=np.zeros(ENVS, np.float32),
        policy_version=learner.version,
        score_only=score_only,
        critic_tasks=tasks if learner.network.spec.critic_task_dim else None,
    )
    return batch, rewards[SCORE_ONLY_ROWS:]


@pytest.mark.parametrize("critic_task_dim", [TASK_DIM, 0], ids=["critic-reads-the-task", "plain-critic"])
def test_a_critic_that_reads_the_task_learns_what_the_task_explains(critic_task_dim):
    spec = PolicySpec(obs_dim=OBS_DIM, action_dim=1, hidden_sizes=(16,), critic_task_dim=critic_task_dim)
    learner = PPOLearner(spec, CONFIG, seed=0)
    for update in range(6):
        learner.update([task_batch(learner, seed=update)[0]])

    batch, returns = task_batch(learner, seed=100)  # unseen steps
    observations = batch.observations[SCORE_ONLY_ROWS:].reshape(-1, OBS_DIM)
    tasks = None if batch.critic_tasks is None else batch.critic_tasks[SCORE_ONLY_ROWS:].reshape(-1, TASK_DIM)
    values = InferencePolicy(learner.snapshot()).value(observations, tasks)
    explained = 1.0 - np.var(returns.reshape(-1) - values) / np.var(returns)
    if critic_task_dim:
        assert explained > 0.9
    else:
        assert explained < 0.1  # the observations are noise: without the task nothing explains the returns


def test_an_update_refuses_batches_without_the_task_its_critic_reads():
    spec = PolicySpec(obs_dim=OBS_DIM, action_dim=1, hidden_sizes=(16,), critic_task_dim=TASK_DIM)
    learner = PPOLearner(spec, CONFIG, seed=0)
    batch = dataclasses.replace(task_batch(learner, seed=0)[0], critic_tasks=None)
    with pytest.raises(ValueError, match="the critic reads 2 task inputs per step, and a batch carries none"):
        learner.update([batch])
