"""A policy's deterministic score on one task, with error bars: the final evaluation of ``evaluate``
and ``bakeoff``.

The deterministic policy (the Gaussian's mean) plays a fixed number of episodes on one task.
Episode ``i`` is seeded ``seed + i`` and the results are put back in episode order, so the figures
depend on the policy, the task and the seed only, never on how many processes shared the work.
Processes are plain CPU workers (no Ray, no teacher): evaluation must work on a laptop with
nothing else running.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from typing import Any, cast

import numpy as np
import torch
from tqdm import tqdm

from common.client.task_space import Task, TaskSpace
from common.kuka import ENV_ID
from common.kuka.env import KukaGraspEnv, make_kuka_env
from common.kuka.task_space import KUKA_TASK_SPACE, task_space_for
from common.policy.actor_critic import InferencePolicy, PolicySnapshot
from common.policy.trajectory import EpisodeStats
from learner.checkpoint import Checkpoint
from learner.kuka_policy import policy_snapshot
from learner.process_pool import StoppablePool
from learner.stats import CONFIDENCE, Interval, mean_interval, wilson_interval
from rollout_worker.sampler import run_episodes


def describe_task(task: Task, space: TaskSpace = KUKA_TASK_SPACE) -> str:
    """'hardest task', or the nearer anchor and what differs from it: 'easiest task with jp2=1'."""
    anchors = {name: getattr(space, name)() for name in ("hardest", "easiest")}
    changes = {
        name: [f"{key}={value:g}" for key, value in task.items() if value != anchor[key]]
        for name, anchor in anchors.items()
    }
    nearest = min(changes, key=lambda name: len(changes[name]))
    return f"{nearest} task" + (f" with {', '.join(changes[nearest])}" if changes[nearest] else "")


@dataclass(frozen=True)
class EvaluationResult:
    task: Task
    seed: int
    episodes: tuple[EpisodeStats, ...]
    env: str = ENV_ID
    """The environment the episodes were played in; ``task`` is a point of its task space."""

    @property
    def returns(self) -> Interval:
        return mean_interval([episode.reward for episode in self.episodes])

    @property
    def success_rate(self) -> Interval:
        return wilson_interval(sum(episode.success for episode in self.episodes), len(self.episodes))

    @property
    def mean_length(self) -> float:
        return float(np.mean([episode.length for episode in self.episodes]))

    def summary(self) -> str:
        returns, success = self.returns, self.success_rate
        spread = "n/a" if math.isnan(returns.half_width) else f"{returns.half_width:.2f}"
        return (
            f"{self._where()}{describe_task(self.task, task_space_for(self.env))}, {len(self.episodes)} episodes: "
            f"return {returns.estimate:.2f} ± {spread} ({CONFIDENCE:.0%} CI), "
            f"success {success.estimate:.0%} [{success.low:.0%}, {success.high:.0%}] (Wilson {CONFIDENCE:.0%}), "
            f"mean length {self.mean_length:.0f}"
        )

    def _where(self) -> str:
        """The environment, named where it is not the default one."""
        return "" if self.env == ENV_ID else f"{self.env}, "

    def to_dict(self) -> dict[str, Any]:
        return {
            "env": self.env,
            "task": self.task,
            "seed": self.seed,
            "episodes": len(self.episodes),
            "confidence": CONFIDENCE,
            "return": self.returns.to_dict(),
            "success_rate": self.success_rate.to_dict(),
            "mean_length": self.mean_length,
            "per_episode": {
                "return": [episode.reward for episode in self.episodes],
                "success": [episode.success for episode in self.episodes],
                "length": [episode.length for episode in self.episodes],
            },
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EvaluationResult:
        env = str(data.get("env", ENV_ID))  # results from before the hard family were all KukaGrasp-v0's
        task = task_space_for(env).validate(data["task"])
        per_episode = data["per_episode"]
        episodes = tuple(
            EpisodeStats(task=task, reward=float(reward), success=bool(success), length=int(length))
            for reward, success, length in zip(
                per_episode["return"], per_episode["success"], per_episode["length"], strict=True
            )
        )
        return cls(task=task, seed=int(data["seed"]), episodes=episodes, env=env)


def available_cpus() -> int:
    """CPUs this process may run on (respects taskset and container limits where the OS reports them)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


_worker: tuple[KukaGraspEnv, InferencePolicy, Task] | None = None
"""Each pool process's environment, policy and task, built once by ``_start_worker``."""


def _start_worker(snapshot: PolicySnapshot, task: Task, max_episode_steps: int, env_id: str) -> None:
    global _worker
    torch.set_num_threads(1)
    _worker = (make_kuka_env(env_id, max_steps=max_episode_steps), InferencePolicy(snapshot), task)


def _play_episode(seed: int) -> EpisodeStats:
    assert _worker is not None, "the pool runs _start_worker in each process before any episode"
    env, policy, task = _worker
    return run_episodes(env, policy, task, [seed])[0]


def evaluate_policy(
    snapshot: PolicySnapshot,
    task: Task,
    episodes: int,
    seed: int = 0,
    processes: int | None = None,
    max_episode_steps: int = 1000,
    progress: bool = True,
    env_id: str = ENV_ID,
) -> EvaluationResult:
    """Play ``episodes`` deterministic episodes of ``env_id``, seeded ``seed``, ``seed + 1``, ...

    ``processes=None`` uses one process per available CPU (at most one per episode); with one,
    the episodes run in this process.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    if processes is not None and processes < 1:
        raise ValueError(f"processes must be at least 1, got {processes}")
    task = task_space_for(env_id).validate(task)
    processes = min(processes or available_cpus(), episodes)
    seeds = [seed + index for index in range(episodes)]
    results: list[EpisodeStats | None] = [None] * episodes
    with tqdm(total=episodes, desc="evaluating", unit="episode", disable=not progress, dynamic_ncols=True) as bar:
        if processes == 1:
            env, policy = make_kuka_env(env_id, max_steps=max_episode_steps), InferencePolicy(snapshot)
            for index, episode_seed in enumerate(seeds):
                results[index] = run_episodes(env, policy, task, [episode_seed])[0]
                bar.update()
            env.close()
        else:
            # spawn, not fork: the parent may hold Ray's and torch's threads, which fork does not copy safely.
            with StoppablePool(
                processes,
                mp_context=get_context("spawn"),
                initializer=_start_worker,
                initargs=(snapshot, task, max_episode_steps, env_id),
            ) as pool:
                futures = {pool.submit(_play_episode, each): index for index, each in enumerate(seeds)}
                for future in as_completed(futures):
                    results[futures[future]] = future.result()
                    bar.update()
    # Every index was filled above: the loop or the pool answered each seed.
    return EvaluationResult(task=task, seed=seed, episodes=tuple(cast(list[EpisodeStats], results)), env=env_id)


def evaluate_checkpoint(
    checkpoint: Checkpoint,
    task: Task,
    episodes: int,
    seed: int = 0,
    processes: int | None = None,
    max_episode_steps: int | None = None,
    progress: bool = True,
) -> EvaluationResult:
    """``evaluate_policy`` on a checkpoint, in the environment it was trained on, with its run's episode
    limit unless one is given."""
    return evaluate_policy(
        policy_snapshot(checkpoint),
        task,
        episodes,
        seed,
        processes,
        max_episode_steps or checkpoint.config.max_episode_steps,
        progress,
        checkpoint.config.env,
    )
