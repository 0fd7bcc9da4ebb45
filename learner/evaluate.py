"""``kuka-curriculum evaluate``: how good is a checkpoint, with error bars.

The deterministic policy (the Gaussian's mean) plays a fixed number of episodes on one task of the
environment it was trained on (the checkpoint records it; ``--task`` names a point of its task space).
Episode ``i`` is seeded ``seed + i`` and the results are put back in episode order, so the figures
depend on the checkpoint, the task and the seed only, never on how many processes shared the work.
Processes are plain CPU workers (no Ray, no teacher): evaluation must work on a laptop with
nothing else running.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pickle
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from tqdm import tqdm

from common import ENV_ID
from common.kuka_env import KukaGraspEnv, make_kuka_env
from common.policy import InferencePolicy, PolicySnapshot
from common.task_space import KUKA_TASK_SPACE, Task, TaskSpace, task_space_for
from common.trajectory import EpisodeStats
from learner.arguments import positive_int
from learner.checkpoint import Checkpoint, latest_checkpoint, load_checkpoint
from learner.network import kuka_policy_spec
from learner.ppo import PPOLearner
from learner.stats import CONFIDENCE, Interval, mean_interval, wilson_interval
from rollout_worker.sampler import run_episodes

TASK_HELP = (
    "'hardest' (the evaluation setting of the checkpoint's environment; for KukaGrasp-v0 the book's), 'easiest', "
    "or name=value overrides on the hardest task, e.g. 'jp2=1.0,rnd_obj_ang=0.5' (start with 'easiest,' to "
    "override the easiest one)"
)


class UsageError(Exception):
    """Bad input: reported in one line, exit code 2."""


def parse_task(text: str, space: TaskSpace = KUKA_TASK_SPACE) -> Task:
    """A task of ``space`` from the command line: an anchor name, optionally followed by ``name=value`` overrides."""
    items = [item.strip() for item in text.split(",") if item.strip()]
    if not items:
        raise ValueError(f"empty task; expected {TASK_HELP}")
    base = space.hardest()
    if "=" not in items[0]:
        anchor = items.pop(0)
        if anchor not in ("hardest", "easiest"):
            raise ValueError(f"unknown task {anchor!r}; expected {TASK_HELP}")
        base = space.hardest() if anchor == "hardest" else space.easiest()
    overrides: dict[str, float] = {}
    for item in items:
        name, separator, value = (part.strip() for part in item.partition("="))
        if not separator or not name:
            names = ", ".join(space.names)
            raise ValueError(f"bad task item {item!r}: expected name=value; names are {names}")
        if name in overrides:
            raise ValueError(f"task parameter {name!r} is given twice")
        try:
            overrides[name] = float(value)
        except ValueError:
            raise ValueError(f"task parameter {name!r} must be a number, got {value!r}") from None
    return space.validate({**base, **overrides})


def checkpoint_task(text: str, checkpoint: Checkpoint) -> Task:
    """``parse_task`` in the task space of the environment the checkpoint was trained on; a bad task
    is a usage error."""
    try:
        return parse_task(text, task_space_for(checkpoint.config.env))
    except ValueError as error:
        raise UsageError(f"--task: {error}") from None


def describe_task(task: Task, space: TaskSpace = KUKA_TASK_SPACE) -> str:
    """'hardest task', or the nearer anchor and what differs from it: 'easiest task with jp2=1'."""
    anchors = {name: getattr(space, name)() for name in ("hardest", "easiest")}
    changes = {
        name: [f"{key}={value:g}" for key, value in task.items() if value != anchor[key]]
        for name, anchor in anchors.items()
    }
    nearest = min(changes, key=lambda name: len(changes[name]))
    return f"{nearest} task" + (f" with {', '.join(changes[nearest])}" if changes[nearest] else "")


def read_checkpoint(path: Path) -> Checkpoint:
    """A checkpoint file as given, or the latest checkpoint of a run directory."""
    path = Path(path)
    if path.is_dir():
        latest = latest_checkpoint(path)
        if latest is None:
            raise UsageError(f"{path} is a directory without checkpoints (expected a run directory or a .pt file)")
        path = latest
    elif not path.is_file():
        raise UsageError(f"no checkpoint at {path}")
    try:
        return load_checkpoint(path)
    except (RuntimeError, pickle.UnpicklingError, KeyError, TypeError, ValueError) as error:
        raise UsageError(f"{path} is not a checkpoint this version can read ({error})") from None


def policy_snapshot(checkpoint: Checkpoint) -> PolicySnapshot:
    """The policy a checkpoint holds, in the form the rollout workers act with."""
    learner = PPOLearner(kuka_policy_spec(checkpoint.config.ppo), checkpoint.config.ppo, checkpoint.config.seed)
    learner.load_state_dict(checkpoint.learner)
    return learner.snapshot()


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
            with ProcessPoolExecutor(
                processes,
                mp_context=get_context("spawn"),
                initializer=_start_worker,
                initargs=(snapshot, task, max_episode_steps, env_id),
            ) as pool:
                futures = {pool.submit(_play_episode, episode_seed): index for index, episode_seed in enumerate(seeds)}
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


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "checkpoint",
        type=Path,
        metavar="CHECKPOINT",
        help="a checkpoint file, or a run directory (its latest checkpoint)",
    )
    parser.add_argument("--episodes", type=positive_int, default=100, help="episodes to play (default 100)")
    parser.add_argument("--task", default="hardest", help=TASK_HELP)
    parser.add_argument("--seed", type=int, default=0, help="episode i is seeded seed + i (default 0)")
    parser.add_argument(
        "--processes", type=positive_int, help=f"worker processes (default: one per CPU, here {available_cpus()})"
    )
    parser.add_argument(
        "--max-episode-steps",
        type=positive_int,
        help="episode step limit (default: the one the checkpoint was trained with)",
    )
    parser.add_argument("--json", type=Path, metavar="PATH", help="also write the results, per episode included, here")


def run(args: argparse.Namespace) -> int:
    try:
        checkpoint = read_checkpoint(args.checkpoint)
        task = checkpoint_task(args.task, checkpoint)
    except UsageError as error:
        print(f"kuka-curriculum evaluate: error: {error}", file=sys.stderr)
        return 2
    result = evaluate_checkpoint(checkpoint, task, args.episodes, args.seed, args.processes, args.max_episode_steps)
    print(f"{checkpoint.path} ({checkpoint.config.teacher}, {checkpoint.counters.steps:_} steps)")
    print(result.summary())
    if args.json is not None:
        write_json(
            args.json,
            {
                "checkpoint": str(checkpoint.path),
                "steps": checkpoint.counters.steps,
                "teacher": checkpoint.config.teacher,
                **result.to_dict(),
            },
        )
    return 0


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write through a temporary file, so an interrupted write never leaves half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    partial.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    os.replace(partial, path)
