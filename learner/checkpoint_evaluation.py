"""A policy's deterministic score on one task, with error bars: the final evaluation of ``evaluate``
and ``bakeoff``.

The deterministic policy (the Gaussian's mean), or the scripted controller it is read against, plays a
fixed number of episodes on one task. Episode ``i`` is seeded ``seed + i`` and the results are put back
in episode order, so the figures depend on the policy, the task and the seed only, never on how many
processes shared the work. Each episode also records where its block lay and how the gripper met it
(``common.kuka.diagnostics``). Processes are plain CPU workers (no Ray, no teacher): evaluation must
work on a laptop with nothing else running.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, fields, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Any, cast, overload

import numpy as np
import torch
from tqdm import tqdm

from common.client.task_space import Task, TaskSpace
from common.kuka import ENV_ID
from common.kuka.diagnostics import Controller, EpisodeDiagnostics, play_episode
from common.kuka.env import KukaGraspEnv, make_kuka_env
from common.kuka.scripted import scripted_action
from common.kuka.task_space import KUKA_TASK_SPACE, task_space_for
from common.policy.actor_critic import InferencePolicy, PolicySnapshot
from common.policy.trajectory import EpisodeStats
from learner.core.checkpoint import Checkpoint
from learner.core.kuka_policy import policy_snapshot
from learner.episode_diagnostics import success_by_band
from learner.json_file import write_json
from learner.process_pool import StoppablePool
from learner.stats import CONFIDENCE, Interval, mean_interval, wilson_interval


def describe_task(task: Task, space: TaskSpace = KUKA_TASK_SPACE) -> str:
    """'hardest task', or the nearer anchor and what differs from it: 'easiest task with jp2=1'."""
    anchors = {name: getattr(space, name)() for name in ("hardest", "easiest")}
    changes = {
        name: [f"{key}={value:g}" for key, value in task.items() if value != anchor[key]]
        for name, anchor in anchors.items()
    }
    nearest = min(changes, key=lambda name: len(changes[name]))
    return f"{nearest} task" + (f" with {', '.join(changes[nearest])}" if changes[nearest] else "")


SIGNIFICANT_DIGITS = 6
"""Digits written of each per-episode float: finer than anything the tables read, and a third fewer bytes
in every archived evaluation than Python's full seventeen."""


@overload
def significant(value: float) -> float: ...
@overload
def significant(value: float | None) -> float | None: ...
def significant(value: float | None) -> float | None:
    """``value`` to ``SIGNIFICANT_DIGITS`` digits, as it is written out and read back."""
    return None if value is None else float(f"{value:.{SIGNIFICANT_DIGITS}g}")


@dataclass(frozen=True)
class EvaluationResult:
    task: Task
    seed: int
    episodes: tuple[EpisodeStats, ...]
    env: str = ENV_ID
    """The environment the episodes were played in; ``task`` is a point of its task space."""
    diagnostics: tuple[EpisodeDiagnostics, ...] = ()
    """Per episode, in the same order; empty for results written before episodes recorded them."""
    max_episode_steps: int | None = None
    """The episodes' step limit; None for results written before it was recorded."""

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

    def diagnosed(self) -> list[tuple[EpisodeDiagnostics, bool]]:
        """Each episode's diagnostics and success, for the placement-band tables; empty without diagnostics."""
        return [
            (diagnostics, episode.success) for diagnostics, episode in zip(self.diagnostics, self.episodes, strict=True)
        ]

    def as_written(self) -> EvaluationResult:
        """This result with its per-episode floats cut to ``SIGNIFICANT_DIGITS``: what ``to_dict`` writes and
        ``from_dict`` reads back, so the file's figures, its placement bands among them, are its own episodes'."""
        return replace(
            self,
            episodes=tuple(replace(episode, reward=significant(episode.reward)) for episode in self.episodes),
            diagnostics=tuple(
                replace(each, **{field.name: significant(getattr(each, field.name)) for field in fields(each)})
                for each in self.diagnostics
            ),
        )

    def to_dict(self) -> dict[str, Any]:
        return self.as_written()._to_dict()

    def _to_dict(self) -> dict[str, Any]:
        diagnostics = [
            {name: significant(value) for name, value in each.to_dict().items()} for each in self.diagnostics
        ]
        return {
            "env": self.env,
            "task": self.task,
            "seed": self.seed,
            "episodes": len(self.episodes),
            **({"max_episode_steps": self.max_episode_steps} if self.max_episode_steps is not None else {}),
            "confidence": CONFIDENCE,
            "return": self.returns.to_dict(),
            "success_rate": self.success_rate.to_dict(),
            "mean_length": self.mean_length,
            "per_episode": {
                "return": [episode.reward for episode in self.episodes],
                "success": [episode.success for episode in self.episodes],
                "length": [episode.length for episode in self.episodes],
                **({name: [each[name] for each in diagnostics] for name in diagnostics[0]} if diagnostics else {}),
            },
            **(
                {"success_by_placement": [band.to_dict() for band in success_by_band(self.diagnosed())]}
                if diagnostics
                else {}
            ),
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
        # Older results lack the diagnostics columns.
        diagnostics = (
            tuple(
                EpisodeDiagnostics.from_dict(
                    {
                        name: per_episode[name][index]
                        for name in (*DIAGNOSTICS_COLUMNS, *LATER_DIAGNOSTICS_COLUMNS)
                        if name in per_episode
                    }
                )
                for index in range(len(episodes))
            )
            if all(name in per_episode for name in DIAGNOSTICS_COLUMNS)
            else ()
        )
        limit = data.get("max_episode_steps")
        return cls(
            task=task,
            seed=int(data["seed"]),
            episodes=episodes,
            env=env,
            diagnostics=diagnostics,
            max_episode_steps=None if limit is None else int(limit),
        )


def pooled_episodes(
    data: dict[str, Any], source: object, played: set[tuple[int, int]]
) -> list[tuple[EpisodeDiagnostics, bool]]:
    """An ``evaluate --json`` result's episodes with their diagnostics, for a table pooled over files: refused
    (ValueError) when ``source`` predates diagnostics or played other episode seeds than the files before it,
    whose (first seed, episodes) ``played`` holds and this one joins."""
    result = EvaluationResult.from_dict(data)
    if not result.diagnostics:
        raise ValueError(f"{source} was written before evaluations recorded placements; evaluate it again")
    played.add((result.seed, len(result.episodes)))
    if len(played) > 1:
        raise ValueError(f"{source} played other episodes than the files before it: {sorted(played)}")
    return result.diagnosed()


def available_cpus() -> int:
    """CPUs this process may run on (respects taskset and container limits where the OS reports them)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


DIAGNOSTICS_COLUMNS = (
    "block_x",
    "block_y",
    "block_yaw",
    "touchdown_block_x",
    "touchdown_block_y",
    "off_square_degrees",
)
"""The ``per_episode`` columns an ``EpisodeDiagnostics`` is read back from (the others are derived)."""
LATER_DIAGNOSTICS_COLUMNS = ("touchdown_wrist_turn_degrees",)
"""Columns read back too where a result has them: results written before they were recorded lack them."""

Played = tuple[EpisodeStats, EpisodeDiagnostics]


def controller(snapshot: PolicySnapshot | None) -> Controller:
    """The deterministic policy of ``snapshot`` (the Gaussian's mean), or the scripted controller for None."""
    if snapshot is None:
        return scripted_action
    policy = InferencePolicy(snapshot)
    return lambda observation: policy.act(observation[None], deterministic=True)[0][0]


_worker: tuple[KukaGraspEnv, Controller, Task] | None = None
"""Each pool process's environment, controller and task, built once by ``_start_worker``."""


def _start_worker(snapshot: PolicySnapshot | None, task: Task, max_episode_steps: int, env_id: str) -> None:
    global _worker
    torch.set_num_threads(1)
    _worker = (make_kuka_env(env_id, max_steps=max_episode_steps), controller(snapshot), task)


def _play(env: KukaGraspEnv, act: Controller, task: Task, seed: int) -> Played:
    episode = play_episode(env, task, act, seed)
    return EpisodeStats(task, episode.reward, episode.success, episode.length), episode.diagnostics


def _play_episode(seed: int) -> Played:
    assert _worker is not None, "the pool runs _start_worker in each process before any episode"
    env, act, task = _worker
    return _play(env, act, task, seed)


def evaluate_policy(
    snapshot: PolicySnapshot | None,
    task: Task,
    episodes: int,
    seed: int = 0,
    processes: int | None = None,
    max_episode_steps: int = 1000,
    progress: bool = True,
    env_id: str = ENV_ID,
) -> EvaluationResult:
    """Play ``episodes`` deterministic episodes of ``env_id``, seeded ``seed``, ``seed + 1``, ...; a
    ``snapshot`` of None plays the scripted controller.

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
    results: list[Played | None] = [None] * episodes
    with tqdm(total=episodes, desc="evaluating", unit="episode", disable=not progress, dynamic_ncols=True) as bar:
        if processes == 1:
            env, act = make_kuka_env(env_id, max_steps=max_episode_steps), controller(snapshot)
            for index, episode_seed in enumerate(seeds):
                results[index] = _play(env, act, task, episode_seed)
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
                for future in pool.as_completed(futures):
                    results[futures[future]] = future.result()
                    bar.update()
    # Every index was filled above: the loop or the pool answered each seed.
    played = cast(list[Played], results)
    # As written: a result's figures, in a bake-off's table or read back from its file, are the same.
    return EvaluationResult(
        task=task,
        seed=seed,
        episodes=tuple(stats for stats, _ in played),
        env=env_id,
        diagnostics=tuple(diagnostics for _, diagnostics in played),
        max_episode_steps=max_episode_steps,
    ).as_written()


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


def scripted_evaluation(
    cache: Path,
    env_id: str,
    episodes: int,
    seed: int,
    processes: int | None = None,
    max_episode_steps: int = 1000,
) -> EvaluationResult:
    """The scripted controller on ``env_id``'s hardest task, the yardstick beside a bake-off's policies,
    read from ``cache`` when it holds the same episodes (environment, task, seeds and step limit) and
    written there when not."""
    task = task_space_for(env_id).hardest()
    if cache.exists():
        cached = EvaluationResult.from_dict(json.loads(cache.read_text(encoding="utf-8")))
        played = (cached.env, cached.task, cached.seed, len(cached.episodes), cached.max_episode_steps)
        if played == (env_id, task, seed, episodes, max_episode_steps) and cached.diagnostics:
            return cached
    result = evaluate_policy(None, task, episodes, seed, processes, max_episode_steps, env_id=env_id)
    write_json(cache, scripted_record(result))
    return result


def scripted_record(result: EvaluationResult) -> dict[str, Any]:
    """The scripted controller's result as written to JSON, marked as the controller's."""
    return {"controller": "scripted", **result.to_dict()}
