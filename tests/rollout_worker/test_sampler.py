import numpy as np
import pytest

from common.client.task_space import Task
from common.client.teacher_client import Assignment
from common.kuka.env import KukaGraspEnv
from common.kuka.task_space import KUKA_TASK_SPACE
from common.policy.actor_critic import ActorCritic, InferencePolicy, PolicySpec, capture_snapshot
from common.policy.normalizer import RunningNormalizer
from common.policy.trajectory import EpisodeStats
from rollout_worker.sampler import Sampler, run_episodes


class RandomTasks:
    """Uniform tasks from the KUKA box; remembers what it handed out and what came back."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.handed_out: list[Task] = []
        self.reported: list[EpisodeStats] = []

    def next_task(self) -> Assignment:
        task = KUKA_TASK_SPACE.from_array(self.rng.uniform(KUKA_TASK_SPACE.low, KUKA_TASK_SPACE.high))
        self.handed_out.append(task)
        return Assignment(f"random:{len(self.handed_out) - 1}", task)

    def report(self, episode: EpisodeStats) -> None:
        self.reported.append(episode)


def make_policy(seed: int = 0) -> InferencePolicy:
    spec = PolicySpec(obs_dim=9, action_dim=3, hidden_sizes=(16, 16))
    return InferencePolicy(capture_snapshot(ActorCritic(spec), RunningNormalizer(9), version=3), seed=seed)


@pytest.fixture()
def envs():
    made = [KukaGraspEnv(max_steps=25) for _ in range(3)]
    yield made
    for env in made:
        env.close()


def test_batches_have_fixed_shape_and_episodes_run_across_batches(envs):
    tasks = RandomTasks(seed=0)
    sampler = Sampler(envs, tasks, seed=0)
    policy = make_policy()
    first, second = sampler.sample(policy, 15), sampler.sample(policy, 15)

    for batch in (first, second):
        assert batch.observations.shape == (15, 3, 9) and batch.actions.shape == (15, 3, 3)
        for name in ("log_probs", "values", "rewards", "terminated", "truncated", "final_values"):
            assert getattr(batch, name).shape == (15, 3), name
        assert batch.last_values.shape == (3,) and batch.policy_version == 3
        assert np.isfinite(batch.observations).all() and np.isfinite(batch.values).all()
    # A 25-step limit falls inside the second batch: every environment truncates exactly once there.
    assert not (first.terminated | first.truncated).any() and not first.episodes
    ended = second.terminated | second.truncated
    assert ended.sum(axis=0).tolist() == [1, 1, 1]
    assert len(second.episodes) == 3 and all(e.length == 25 for e in second.episodes)
    # Bootstrap values exist exactly where an episode was cut short by the limit.
    assert ((second.final_values != 0) == second.truncated).all()


def test_each_episode_is_reported_once_with_its_own_task_return_and_length(envs):
    tasks = RandomTasks(seed=1)
    sampler = Sampler(envs, tasks, seed=1)
    batch = sampler.sample(make_policy(), 60)
    assert tasks.reported == batch.episodes

    # Replay the episode ends the batch records, in the order they happened.
    current_tasks, handed_out = list(tasks.handed_out[:3]), iter(tasks.handed_out[3:])
    episode_start = [0, 0, 0]
    expected = []
    for step, env_index in zip(*np.nonzero(batch.terminated | batch.truncated), strict=True):
        rewards = batch.rewards[episode_start[env_index] : step + 1, env_index]
        task_index = tasks.handed_out.index(current_tasks[env_index])
        expected.append(
            (f"random:{task_index}", current_tasks[env_index], pytest.approx(rewards.sum(), rel=1e-5), len(rewards))
        )
        current_tasks[env_index] = next(handed_out)
        episode_start[env_index] = step + 1
    assert len(expected) >= 6
    assert [(e.task_id, e.task, e.reward, e.length) for e in batch.episodes] == expected
    assert next(handed_out, None) is None


def test_evaluation_episodes_repeat_exactly_for_the_same_seeds():
    env = KukaGraspEnv(max_steps=40)
    policy = make_policy()
    hardest = KUKA_TASK_SPACE.hardest()
    first = run_episodes(env, policy, hardest, seeds=[5, 6])
    again = run_episodes(env, policy, hardest, seeds=[5, 6])
    env.close()
    assert first == again
    assert [e.task for e in first] == [hardest, hardest]
    assert all(e.length == 40 for e in first)
