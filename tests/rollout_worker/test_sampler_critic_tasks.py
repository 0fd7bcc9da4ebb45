"""The sampler feeds a critic that reads the task each environment's current task, scaled to [0, 1] by the
run's task space, and the batch carries those inputs for the learner: the episode's own task at every step,
the ended episode's for a truncated episode's bootstrap value, the running one's for the batch's last values."""

import numpy as np
import pytest
import torch

from common.client.task_space import Task
from common.client.teacher_client import Assignment
from common.kuka.env import KukaGraspEnv
from common.kuka.task_space import KUKA_TASK_SPACE
from common.policy.actor_critic import ActorCritic, InferencePolicy, PolicySpec, capture_snapshot
from common.policy.normalizer import RunningNormalizer
from common.policy.trajectory import EpisodeStats
from rollout_worker.sampler import Sampler, run_episodes

TASK_DIM = len(KUKA_TASK_SPACE)


class RandomTasks:
    """Uniform tasks from the book's KUKA box, in the order handed out."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.handed_out: list[Task] = []

    def next_task(self) -> Assignment:
        task = KUKA_TASK_SPACE.from_array(self.rng.uniform(KUKA_TASK_SPACE.low, KUKA_TASK_SPACE.high))
        self.handed_out.append(task)
        return Assignment(f"random:{len(self.handed_out) - 1}", task)

    def report(self, episode: EpisodeStats) -> None:
        pass


def task_only_critic() -> InferencePolicy:
    """A policy whose critic reads the task alone (its weights on the observation's features are zero), so a
    value tells which task it was computed with."""
    spec = PolicySpec(obs_dim=9, action_dim=3, hidden_sizes=(16,), critic_task_dim=TASK_DIM)
    torch.manual_seed(0)
    network = ActorCritic(spec)
    with torch.no_grad():
        network.critic[0].weight.mul_(5.0)[:, : spec.feature_dim] = 0.0
    return InferencePolicy(capture_snapshot(network, RunningNormalizer(spec.feature_dim), version=1), seed=0)


def unit(task: Task) -> np.ndarray:
    return KUKA_TASK_SPACE.to_unit(KUKA_TASK_SPACE.to_array(task)).astype(np.float32)


@pytest.fixture()
def envs():
    made = [KukaGraspEnv(max_steps=25) for _ in range(3)]
    yield made
    for env in made:
        env.close()


def test_each_value_is_computed_with_its_own_episodes_task(envs):
    tasks, policy = RandomTasks(), task_only_critic()
    sampler = Sampler(envs, tasks, seed=0, task_space=KUKA_TASK_SPACE)
    first, second = sampler.sample(policy, 15), sampler.sample(policy, 15)

    def value_of(critic_tasks: np.ndarray) -> np.ndarray:
        return policy.value(np.zeros((len(critic_tasks), 9), np.float32), critic_tasks)

    for batch in (first, second):
        assert batch.critic_tasks is not None and batch.critic_tasks.shape == (15, 3, TASK_DIM)
        assert batch.critic_tasks.dtype == np.float32 and ((batch.critic_tasks >= 0) & (batch.critic_tasks <= 1)).all()
        assert batch.values == pytest.approx(value_of(batch.critic_tasks.reshape(-1, TASK_DIM)).reshape(15, 3))
        assert batch.last_values == pytest.approx(value_of(batch.critic_tasks[-1]))  # no episode ends at the last step
    assert np.array_equal(first.critic_tasks[0], np.stack([unit(task) for task in tasks.handed_out[:3]]))
    # The 25-step limit cuts every episode at the second batch's step 9: its bootstrap value is the ended
    # episode's, whose task the result reports; from step 10 on the environments play their next tasks.
    assert second.truncated[9].all() and len(second.episodes) == 3
    ended = second.critic_tasks[9]
    assert np.array_equal(ended, np.stack([unit(episode.task) for episode in second.episodes]))
    assert second.final_values[9] == pytest.approx(value_of(ended))
    assert np.array_equal(second.critic_tasks[10], np.stack([unit(task) for task in tasks.handed_out[3:6]]))
    assert not np.allclose(second.final_values[9], value_of(second.critic_tasks[10]), atol=1e-3)


def test_a_critic_that_reads_the_task_needs_the_runs_task_space(envs):
    with pytest.raises(ValueError, match=f"reads {TASK_DIM} task parameters; this sampler was given no task space"):
        Sampler(envs, RandomTasks(), seed=0).sample(task_only_critic(), 2)


def test_without_a_critic_that_reads_the_task_batches_carry_none(envs):
    spec = PolicySpec(obs_dim=9, action_dim=3, hidden_sizes=(16,))
    policy = InferencePolicy(capture_snapshot(ActorCritic(spec), RunningNormalizer(9), version=0), seed=0)
    assert Sampler(envs, RandomTasks(), seed=0, task_space=KUKA_TASK_SPACE).sample(policy, 3).critic_tasks is None


def test_evaluation_episodes_act_with_the_actor_alone(envs):
    episodes = run_episodes(envs[0], task_only_critic(), KUKA_TASK_SPACE.hardest(), seeds=[0, 1])
    assert [episode.length for episode in episodes] == [25, 25] and all(np.isfinite(e.reward) for e in episodes)
