"""The sampling loop: several environments stepped in lockstep with one batched policy call.

Knows nothing of Ray or HTTP: tasks come from, and finished episodes go to, any ``TaskSource``.
Episodes run across ``sample`` calls, so a batch boundary never cuts an episode short.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, cast

import gymnasium as gym
import numpy as np

from common.client.task_space import Task
from common.policy.inference import InferencePolicy
from common.policy.trajectory import EpisodeStats, TrajectoryBatch


class TaskSource(Protocol):
    """Where episodes get their task and where their results go."""

    def next_task(self) -> tuple[str | None, Task]:
        """The task for the next episode, with the id its result is reported under (None: no id)."""
        ...

    def report(self, episode: EpisodeStats) -> None: ...


class Sampler:
    """Owns a set of environments and their in-progress episodes."""

    def __init__(self, envs: Sequence[gym.Env[np.ndarray, np.ndarray]], tasks: TaskSource, seed: int) -> None:
        if not envs:
            raise ValueError("a sampler needs at least one environment")
        self.envs = list(envs)
        self.tasks = tasks
        space = cast(gym.spaces.Box, self.envs[0].action_space)  # actions are clipped into its bounds
        self._action_low, self._action_high = space.low, space.high
        num_envs = len(self.envs)
        self._episode_tasks: list[tuple[str | None, Task]] = [(None, {}) for _ in range(num_envs)]
        self._returns = np.zeros(num_envs, dtype=np.float64)
        self._lengths = np.zeros(num_envs, dtype=np.int64)
        env_seeds = np.random.SeedSequence(seed).generate_state(num_envs)
        self._observations = np.stack(
            [self._start_episode(index, seed=int(env_seed)) for index, env_seed in enumerate(env_seeds)]
        ).astype(np.float32)

    def _start_episode(self, index: int, seed: int | None = None) -> np.ndarray:
        task_id, task = self.tasks.next_task()
        self._episode_tasks[index] = (task_id, task)
        self._returns[index] = 0.0
        self._lengths[index] = 0
        observation, _ = self.envs[index].reset(seed=seed, options={"task": task})
        return observation

    def _finish_episode(self, index: int, info: dict[str, Any]) -> EpisodeStats:
        task_id, task = self._episode_tasks[index]
        episode = EpisodeStats(
            task=task,
            reward=float(self._returns[index]),
            success=bool(info.get("is_success", False)),
            length=int(self._lengths[index]),
            task_id=task_id,
        )
        self.tasks.report(episode)
        return episode

    def sample(self, policy: InferencePolicy, num_steps: int) -> TrajectoryBatch:
        """Step every environment ``num_steps`` times and return the batch."""
        num_envs = len(self.envs)
        obs_dim = self._observations.shape[1]
        action_dim = self._action_low.shape[0]
        observations = np.zeros((num_steps, num_envs, obs_dim), dtype=np.float32)
        actions = np.zeros((num_steps, num_envs, action_dim), dtype=np.float32)
        log_probs, values, rewards, final_values = (np.zeros((num_steps, num_envs), dtype=np.float32) for _ in range(4))
        terminated, truncated = (np.zeros((num_steps, num_envs), dtype=bool) for _ in range(2))
        episodes: list[EpisodeStats] = []

        for step in range(num_steps):
            observations[step] = self._observations
            actions[step], log_probs[step], values[step] = policy.act(self._observations)
            env_actions = np.clip(actions[step], self._action_low, self._action_high)
            cut_short: list[tuple[int, np.ndarray]] = []
            for index, env in enumerate(self.envs):
                observation, reward, ended, timed_out, info = env.step(env_actions[index])
                rewards[step, index] = reward
                terminated[step, index] = ended
                truncated[step, index] = timed_out and not ended
                self._returns[index] += reward
                self._lengths[index] += 1
                if ended or timed_out:
                    if not ended:
                        cut_short.append((index, observation))
                    episodes.append(self._finish_episode(index, info))
                    observation = self._start_episode(index)
                self._observations[index] = observation
            if cut_short:
                indices, final_observations = zip(*cut_short, strict=True)
                final_values[step, list(indices)] = policy.value(np.stack(final_observations))

        return TrajectoryBatch(
            observations=observations,
            actions=actions,
            log_probs=log_probs,
            values=values,
            rewards=rewards,
            terminated=terminated,
            truncated=truncated,
            final_values=final_values,
            last_values=policy.value(self._observations),
            policy_version=policy.version,
            episodes=episodes,
        )


def run_episodes(
    env: gym.Env[np.ndarray, np.ndarray],
    policy: InferencePolicy,
    task: Task,
    seeds: Sequence[int],
    deterministic: bool = True,
) -> list[EpisodeStats]:
    """Play one whole episode per seed on a fixed task (evaluation: nothing is reported anywhere)."""
    results = []
    space = cast(gym.spaces.Box, env.action_space)  # actions are clipped into its bounds
    low, high = space.low, space.high
    for seed in seeds:
        observation, info = env.reset(seed=int(seed), options={"task": task})
        total, length, done = 0.0, 0, False
        while not done:
            action, _, _ = policy.act(observation[None], deterministic=deterministic)
            observation, reward, ended, timed_out, info = env.step(np.clip(action[0], low, high))
            total += float(reward)
            length += 1
            done = ended or timed_out
        success = bool(info.get("is_success", False))
        results.append(EpisodeStats(task=task, reward=total, success=success, length=length))
    return results
