"""A policy's score on one task, with error bars: the final evaluation of ``evaluate`` and ``bakeoff``.

The policy acts as its family evaluates (the Gaussian's mean; a categorical policy samples), or the scripted
controller it is read against on a KUKA family plays, for a fixed number of episodes on one task (none: held-out
levels). Episode ``i`` plays the family's ``i``-th episode seed from ``seed`` and the results are put back in
episode order; a sampling policy draws from a generator seeded by the episode's seed, so the figures depend on
the policy, the task and the seed only, never on how many processes shared the work. On a KUKA family each
episode also records where its block lay and how the gripper met it (``common.kuka.diagnostics``). Processes are
plain CPU workers (no Ray, no teacher): evaluation must work on a laptop with nothing else running.
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

from common.client.task_space import MAX_LEVELS, Task, TaskSpace
from common.families import TaskFamily, family_for
from common.families.base import Controller, is_level_space
from common.kuka import ENV_ID
from common.kuka.diagnostics import EpisodeDiagnostics
from common.kuka.task_space import KUKA_TASK_SPACE
from common.levels import DEFAULT_LEVELS
from common.policy.actor_critic import InferencePolicy, PolicySnapshot
from common.policy.trajectory import EpisodeStats
from learner.core.checkpoint import Checkpoint
from learner.core.json_file import write_json
from learner.core.policy import policy_snapshot
from learner.evaluation.episode_diagnostics import success_by_band
from learner.evaluation.process_pool import StoppablePool
from learner.evaluation.stats import CONFIDENCE, Interval, mean_interval, wilson_interval


def describe_task(task: Task, space: TaskSpace = KUKA_TASK_SPACE) -> str:
    """'hardest task', or the nearer anchor and what differs from it: 'easiest task with jp2=1'; on a level
    space 'held-out levels' (no task) or the level."""
    if not task:
        return "held-out levels"
    if is_level_space(space):
        return ", ".join(f"{name} {value:g}" for name, value in task.items())
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
            f"{self._where()}{describe_task(self.task, self.task_space())}, {len(self.episodes)} episodes: "
            f"return {returns.estimate:.2f} ± {spread} ({CONFIDENCE:.0%} CI), "
            f"success {success.estimate:.0%} [{success.low:.0%}, {success.high:.0%}] (Wilson {CONFIDENCE:.0%}), "
            f"mean length {self.mean_length:.0f}"
        )

    def task_space(self) -> TaskSpace:
        """The space ``task`` is a point of (a MiniGrid family's at its largest training set, which holds the
        level of any run's task)."""
        return family_for(self.env).task_space(self.env, MAX_LEVELS)

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
        task = dict(data["task"])
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
        result = cls(
            task=task,
            seed=int(data["seed"]),
            episodes=episodes,
            env=env,
            diagnostics=diagnostics,
            max_episode_steps=None if limit is None else int(limit),
        )
        return replace(result, task=result.task_space().validate(task)) if task else result


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

Played = tuple[EpisodeStats, EpisodeDiagnostics | None]
"""An episode's figures, and its diagnostics where its family records them (KUKA's)."""


class _Player:
    """Plays one episode per seed on one environment: the family's way (with diagnostics on a KUKA family), the
    policy acting as the family evaluates, or the family's scripted controller for no snapshot."""

    def __init__(self, family: TaskFamily, env_id: str, snapshot: PolicySnapshot | None, max_steps: int) -> None:
        self.family = family
        self.env = family.make_env(env_id, max_steps)
        self.policy = None if snapshot is None else InferencePolicy(snapshot)
        self.act: Controller = family.scripted_controller(env_id) if snapshot is None else self._policy_action

    def _policy_action(self, observation: np.ndarray) -> np.ndarray:
        assert self.policy is not None
        action: np.ndarray = self.policy.act(observation[None], self.family.deterministic_evaluation)[0][0]
        return action

    def play(self, task: Task, seed: int) -> Played:
        if self.policy is not None:
            self.policy.rng = np.random.default_rng(seed)  # a sampling policy's draws belong to its episode
        episode = self.family.play_episode(self.env, task, self.act, seed)
        stats = EpisodeStats(task, episode.reward, episode.success, episode.length)
        return stats, cast(EpisodeDiagnostics | None, episode.diagnostics)

    def close(self) -> None:
        self.env.close()  # type: ignore[no-untyped-call]  # gymnasium's Env.close is unannotated


_worker: tuple[_Player, Task] | None = None
"""Each pool process's player and task, built once by ``_start_worker``."""


def _start_worker(snapshot: PolicySnapshot | None, task: Task, max_episode_steps: int, env_id: str) -> None:
    global _worker
    torch.set_num_threads(1)
    _worker = (_Player(family_for(env_id), env_id, snapshot, max_episode_steps), task)


def _play_episode(seed: int) -> Played:
    assert _worker is not None, "the pool runs _start_worker in each process before any episode"
    player, task = _worker
    return player.play(task, seed)


def evaluate_policy(
    snapshot: PolicySnapshot | None,
    task: Task,
    episodes: int,
    seed: int = 0,
    processes: int | None = None,
    max_episode_steps: int = 1000,
    progress: bool = True,
    env_id: str = ENV_ID,
    levels: int = DEFAULT_LEVELS,
) -> EvaluationResult:
    """Play ``episodes`` episodes of ``env_id`` on ``task`` from the family's episode seeds for ``seed``
    (``seed``, ``seed + 1``, ...; held-out levels on a level space); a ``snapshot`` of None plays the scripted
    controller. ``levels`` sizes a MiniGrid family's task space, in which ``task`` is checked.

    ``processes=None`` uses one process per available CPU (at most one per episode); with one,
    the episodes run in this process.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    if processes is not None and processes < 1:
        raise ValueError(f"processes must be at least 1, got {processes}")
    family = family_for(env_id)
    task = family.task_space(env_id, levels).validate(task) if task else task
    processes = min(processes or available_cpus(), episodes)
    seeds = family.episode_seeds(env_id, levels, seed, episodes)
    results: list[Played | None] = [None] * episodes
    with tqdm(total=episodes, desc="evaluating", unit="episode", disable=not progress, dynamic_ncols=True) as bar:
        if processes == 1:
            player = _Player(family, env_id, snapshot, max_episode_steps)
            for index, episode_seed in enumerate(seeds):
                results[index] = player.play(task, episode_seed)
                bar.update()
            player.close()
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
    diagnostics = tuple(each for _, each in played if each is not None)
    # As written: a result's figures, in a bake-off's table or read back from its file, are the same.
    return EvaluationResult(
        task=task,
        seed=seed,
        episodes=tuple(stats for stats, _ in played),
        env=env_id,
        diagnostics=diagnostics if len(diagnostics) == episodes else (),
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
        checkpoint.config.levels,
    )


def checkpoint_record(checkpoint: Checkpoint, result: EvaluationResult) -> dict[str, Any]:
    """A checkpoint's evaluation as ``evaluate --json`` writes it: which checkpoint played, then the result."""
    return {
        "checkpoint": str(checkpoint.path),
        "steps": checkpoint.counters.steps,
        "teacher": checkpoint.config.teacher,
        **result.to_dict(),
    }


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
    task = family_for(env_id).evaluation_task(env_id, DEFAULT_LEVELS)
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
