"""The sampling loop: several environments stepped in lockstep with one batched policy call.

Knows nothing of Ray or HTTP: tasks come from, and finished episodes go to, any ``TaskSource``.
Episodes run across ``sample`` calls, so a batch boundary never cuts an episode short. Actions are a
box's (clipped into it) or a ``Discrete`` space's (a categorical policy's indices). Given the PPO
config's discount (``ScoreDiscount``), each finished episode carries its score (robust PLR's positive value
loss or the PLR paper's ``value_l1``), computed here from its rewards and predicted values, since only the
worker sees whole episodes; and an episode whose task is score-only has its steps marked in the batch,
for the learner to leave out. Given the run's task space, it feeds a critic that reads the task
(``PolicySpec.critic_task_dim``) each environment's current task, scaled to [0, 1], and the batch carries
those inputs for the learner's critic.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol, cast

import gymnasium as gym
import numpy as np

from common.client.task_space import Task, TaskSpace
from common.client.teacher_client import Assignment
from common.families.base import env_action
from common.policy.inference import InferencePolicy
from common.policy.trajectory import EpisodeStats, TrajectoryBatch


class TaskSource(Protocol):
    """Where episodes get their task and where their results go."""

    def next_task(self) -> Assignment:
        """The task for the next episode, with the id its result is reported under (None: no id) and
        whether it is for scoring only."""
        ...

    def report(self, episode: EpisodeStats) -> None: ...


EpisodeScore = Literal["positive_value_loss", "value_l1"]


@dataclass(frozen=True)
class ScoreDiscount:
    """How episodes are scored: the discount and GAE lambda of the learner's PPO config, and which score
    (``EPISODE_SCORES``; ``PPOConfig.level_score``)."""

    gamma: float
    gae_lambda: float
    score: EpisodeScore = "positive_value_loss"

    def __post_init__(self) -> None:
        if self.score not in EPISODE_SCORES:
            raise ValueError(f"score must be one of {', '.join(EPISODE_SCORES)}, got {self.score!r}")


SCORE_BLOCK = 128
"""Steps per block of ``discounted_suffix_sums``: one (block x block) product each."""


def discounted_suffix_sums(values: np.ndarray, discount: float) -> np.ndarray:
    """``out[t] = sum over k >= t of discount**(k - t) * values[k]``, vectorised: each block of
    ``SCORE_BLOCK`` steps from the end is one product with an upper-triangular matrix of powers, plus the
    next block's first sum carried in. No negative powers, so no overflow for long episodes."""
    n = len(values)
    block = min(n, SCORE_BLOCK)
    offsets = np.arange(block)
    lags = offsets[None, :] - offsets[:, None]
    powers = np.where(lags >= 0, discount ** np.maximum(lags, 0), 0.0)
    tail = discount ** (block - offsets)  # from each step of a block to the first of the next
    out = np.empty(n, dtype=np.float64)
    carried = 0.0
    for end in range(n, 0, -block):
        start = max(end - block, 0)
        size = end - start
        out[start:end] = powers[:size, :size] @ values[start:end] + tail[block - size :] * carried
        carried = out[start]
    return out


def episode_advantages(
    rewards: np.ndarray, values: np.ndarray, bootstrap: float, discount: ScoreDiscount
) -> np.ndarray:
    """One whole episode's GAE advantages, with ``bootstrap`` the value after its last step (0 when it
    terminated, V of its last observation when it was cut short)."""
    values = values.astype(np.float64)
    next_values = np.append(values[1:], bootstrap)
    deltas = rewards.astype(np.float64) + discount.gamma * next_values - values
    return discounted_suffix_sums(deltas, discount.gamma * discount.gae_lambda)


def positive_value_loss(rewards: np.ndarray, values: np.ndarray, bootstrap: float, discount: ScoreDiscount) -> float:
    """The mean over the episode's steps of max(GAE advantage, 0): robust PLR's score (Jiang et al. 2021b)."""
    return float(np.maximum(episode_advantages(rewards, values, bootstrap, discount), 0.0).mean())


def value_l1(rewards: np.ndarray, values: np.ndarray, bootstrap: float, discount: ScoreDiscount) -> float:
    """The mean over the episode's steps of |GAE advantage|: the PLR paper's score (Jiang et al. 2021a), and
    the strategy of Syllabus's PLR example."""
    return float(np.abs(episode_advantages(rewards, values, bootstrap, discount)).mean())


EPISODE_SCORES = {"positive_value_loss": positive_value_loss, "value_l1": value_l1}
"""The scores a worker can send, by name: ``ScoreDiscount.score`` picks one."""


class Sampler:
    """Owns a set of environments and their in-progress episodes."""

    def __init__(
        self,
        envs: Sequence[gym.Env[np.ndarray, Any]],
        tasks: TaskSource,
        seed: int,
        score_discount: ScoreDiscount | None = None,
        task_space: TaskSpace | None = None,
    ) -> None:
        """``score_discount``: score each finished episode with it (None: no scores). ``task_space``: the run's,
        which scales each episode's task for a critic that reads it (None: only policies whose critic does not)."""
        if not envs:
            raise ValueError("a sampler needs at least one environment")
        self.envs = list(envs)
        self.tasks = tasks
        self.score_discount = score_discount
        self.task_space = task_space
        space = self.envs[0].action_space
        self._discrete = isinstance(space, gym.spaces.Discrete)
        if not self._discrete:
            box = cast(gym.spaces.Box, space)  # actions are clipped into its bounds
            self._action_low, self._action_high = box.low, box.high
        self._action_dim = 1 if self._discrete else self._action_low.shape[0]
        num_envs = len(self.envs)
        self._episode_tasks: list[Assignment] = [Assignment(None, {}) for _ in range(num_envs)]
        self._score_only = np.zeros(num_envs, dtype=bool)
        self._returns = np.zeros(num_envs, dtype=np.float64)
        self._lengths = np.zeros(num_envs, dtype=np.int64)
        self._carried: list[tuple[np.ndarray, np.ndarray]] = [_NOTHING_CARRIED] * num_envs
        """Per environment, the rewards and values of its episode's steps in earlier batches (for its score)."""
        self._critic_tasks = None if task_space is None else np.zeros((num_envs, len(task_space)), dtype=np.float32)
        """Per environment, its episode's task scaled to [0, 1] by ``task_space``: what a critic that reads it reads."""
        env_seeds = np.random.SeedSequence(seed).generate_state(num_envs)
        self._observations = np.stack(
            [self._start_episode(index, seed=int(env_seed)) for index, env_seed in enumerate(env_seeds)]
        ).astype(np.float32)

    def _start_episode(self, index: int, seed: int | None = None) -> np.ndarray:
        assignment = self.tasks.next_task()
        self._episode_tasks[index] = assignment
        self._score_only[index] = assignment.score_only
        if self.task_space is not None and self._critic_tasks is not None:
            self._critic_tasks[index] = self.task_space.to_unit(self.task_space.to_array(assignment.params))
        self._returns[index] = 0.0
        self._lengths[index] = 0
        observation, _ = self.envs[index].reset(seed=seed, options={"task": assignment.params})
        return observation

    def _finish_episode(self, index: int, info: dict[str, Any], score: float | None) -> EpisodeStats:
        assignment = self._episode_tasks[index]
        episode = EpisodeStats(
            task=assignment.params,
            reward=float(self._returns[index]),
            success=bool(info.get("is_success", False)),
            length=int(self._lengths[index]),
            task_id=assignment.task_id,
            score=score,
            score_only=assignment.score_only,
        )
        self.tasks.report(episode)
        return episode

    def sample(self, policy: InferencePolicy, num_steps: int) -> TrajectoryBatch:
        """Step every environment ``num_steps`` times and return the batch."""
        tasks_now = self._critic_inputs(policy)
        num_envs = len(self.envs)
        obs_dim = self._observations.shape[1]
        observations = np.zeros((num_steps, num_envs, obs_dim), dtype=np.float32)
        actions = np.zeros((num_steps, num_envs, self._action_dim), dtype=np.float32)
        log_probs, values, rewards, final_values = (np.zeros((num_steps, num_envs), dtype=np.float32) for _ in range(4))
        terminated, truncated, score_only = (np.zeros((num_steps, num_envs), dtype=bool) for _ in range(3))
        critic_tasks = None if tasks_now is None else np.zeros((num_steps, *tasks_now.shape), dtype=np.float32)
        episode_starts = np.zeros(num_envs, dtype=np.int64)
        episodes: list[EpisodeStats] = []

        for step in range(num_steps):
            observations[step] = self._observations
            score_only[step] = self._score_only
            if critic_tasks is not None:
                critic_tasks[step] = tasks_now
            actions[step], log_probs[step], values[step] = policy.act(self._observations, critic_tasks=tasks_now)
            if self._discrete:
                env_actions = actions[step, :, 0].astype(np.int64)
            else:
                env_actions = np.clip(actions[step], self._action_low, self._action_high)
            cut_short: list[tuple[int, np.ndarray]] = []
            ended_here: list[tuple[int, dict[str, Any]]] = []
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
                    ended_here.append((index, info))
                else:
                    self._observations[index] = observation
            if cut_short:
                indices, final_observations = zip(*cut_short, strict=True)
                ended_tasks = None if tasks_now is None else tasks_now[list(indices)]  # before the next task is drawn
                final_values[step, list(indices)] = policy.value(np.stack(final_observations), ended_tasks)
            # Each episode's result goes out, and its environment's next task is drawn, once the step's
            # bootstrap values are known: its score needs the value after its last step.
            for index, info in ended_here:
                score = None
                if self.score_discount is not None:
                    score = self._score(index, rewards, values, episode_starts[index], step, final_values[step, index])
                    episode_starts[index] = step + 1
                episodes.append(self._finish_episode(index, info, score))
                self._observations[index] = self._start_episode(index)

        if self.score_discount is not None:
            for index in range(num_envs):
                self._carry(index, rewards, values, episode_starts[index])
        return TrajectoryBatch(
            observations=observations,
            actions=actions,
            log_probs=log_probs,
            values=values,
            rewards=rewards,
            terminated=terminated,
            truncated=truncated,
            final_values=final_values,
            last_values=policy.value(self._observations, tasks_now),
            policy_version=policy.version,
            episodes=episodes,
            score_only=score_only if score_only.any() else None,
            critic_tasks=critic_tasks,
        )

    def _critic_inputs(self, policy: InferencePolicy) -> np.ndarray | None:
        """The environments' current tasks as ``policy``'s critic reads them (updated in place as episodes
        start), or None where it reads none."""
        wanted = policy.spec.critic_task_dim
        if not wanted:
            return None
        if self._critic_tasks is None or self._critic_tasks.shape[1] != wanted:
            have = "no task space" if self._critic_tasks is None else f"a task space of {self._critic_tasks.shape[1]}"
            raise ValueError(f"the policy's critic reads {wanted} task parameters; this sampler was given {have}")
        return self._critic_tasks

    def _score(
        self, index: int, rewards: np.ndarray, values: np.ndarray, start: int, step: int, bootstrap: float
    ) -> float:
        """The score of the episode that environment ``index`` ended at ``step``: its steps in earlier batches
        and this one's from ``start``; ``bootstrap`` is 0 unless it was cut short."""
        assert self.score_discount is not None
        earlier_rewards, earlier_values = self._carried[index]
        self._carried[index] = _NOTHING_CARRIED
        episode_rewards = np.concatenate([earlier_rewards, rewards[start : step + 1, index]])
        episode_values = np.concatenate([earlier_values, values[start : step + 1, index]])
        score = EPISODE_SCORES[self.score_discount.score]
        return score(episode_rewards, episode_values, float(bootstrap), self.score_discount)

    def _carry(self, index: int, rewards: np.ndarray, values: np.ndarray, start: int) -> None:
        """Keep the unfinished episode's steps of this batch, from ``start``, for its score."""
        earlier_rewards, earlier_values = self._carried[index]
        self._carried[index] = (
            np.concatenate([earlier_rewards, rewards[start:, index]]),
            np.concatenate([earlier_values, values[start:, index]]),
        )


_NOTHING_CARRIED = (np.zeros(0, dtype=np.float32), np.zeros(0, dtype=np.float32))


def run_episodes(
    env: gym.Env[np.ndarray, Any],
    policy: InferencePolicy,
    task: Task,
    seeds: Sequence[int],
    deterministic: bool = True,
) -> list[EpisodeStats]:
    """Play one whole episode per seed on a fixed task (evaluation: nothing is reported anywhere). The actor
    acts alone: no values are needed, so a critic that reads the task is never asked (``InferencePolicy.act``)."""
    results = []
    for seed in seeds:
        observation, info = env.reset(seed=int(seed), options={"task": task})
        total, length, done = 0.0, 0, False
        while not done:
            action, _, _ = policy.act(observation[None], deterministic=deterministic)
            observation, reward, ended, timed_out, info = env.step(env_action(env.action_space, action[0]))
            total += float(reward)
            length += 1
            done = ended or timed_out
        success = bool(info.get("is_success", False))
        results.append(EpisodeStats(task=task, reward=total, success=success, length=length))
    return results
