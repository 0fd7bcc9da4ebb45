"""How hard each point of a KUKA task family is for policies that learn nothing: the figures that say
whether the reward can be found by chance.

Three fixed policies play the same episodes (episode ``i`` is seeded ``seed + i``) on several points
of the family, from the easiest to the hardest:
- ``zero``: no action; the gripper descends where it starts;
- ``random``: uniform random actions, as an untrained explorer;
- ``drift``: PPO's starting action noise (Gaussian, std ``DRIFT_STD``) around a mean x/y move drawn
  once per episode, uniform in [-1, 1]^2: a policy whose mean has drifted, as PPO's does while its
  advantages are noise, ends its descent wherever that mean carries it, the box's edges included;
- ``scripted``: a hand-made controller that reads only the observation, moves the gripper over the
  block and turns the wrist across it: it shows the point can be solved, not how well PPO can.

    .venv/bin/python bench/task_hardness.py --env KukaGraspHard-v0 --episodes 1000 --processes 2

Prints, per point and policy, the success rate (Wilson 95% interval), the mean return and the mean
episode length; ``--json`` also writes them.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: the checkout's packages
from common.client.task_space import Task  # noqa: E402
from common.kuka import ENV_IDS, HARD_ENV_ID, HARD_V1_ENV_ID  # noqa: E402
from common.kuka.env import KukaGraspEnv, make_kuka_env  # noqa: E402
from common.kuka.scripted import scripted_action  # noqa: E402
from common.kuka.task_space import KUKA_HARD_BOOK_HARDEST, MOVE_SCALE_HARDEST, task_space_for  # noqa: E402
from learner.evaluation.process_pool import StoppablePool  # noqa: E402
from learner.evaluation.stats import wilson_interval  # noqa: E402

POLICIES = ("zero", "random", "drift", "scripted")
CHUNK = 50
"""Episodes per unit of work handed to a process."""
DRIFT_STD = math.exp(-0.5)
"""Drift policy: the action noise of an untrained policy (``PPOConfig.init_log_std`` -0.5)."""

Policy = Callable[[np.ndarray], np.ndarray]
"""Observation to action, for one episode."""


def episode_policy(name: str, rng: np.random.Generator) -> Policy:
    """The named policy for one episode, its randomness drawn from ``rng``."""
    if name == "zero":
        return lambda observation: np.zeros(3, dtype=np.float32)
    if name == "random":
        return lambda observation: rng.uniform(-1.0, 1.0, size=3).astype(np.float32)
    if name == "drift":
        mean = np.array([*rng.uniform(-1.0, 1.0, size=2), 0.0])
        return lambda observation: np.clip(mean + DRIFT_STD * rng.standard_normal(3), -1.0, 1.0).astype(np.float32)
    return scripted_action


def run_episode(env: KukaGraspEnv, task: Task, act: Policy, seed: int) -> tuple[dict[str, Any], float, int, np.ndarray]:
    """One episode of ``act``: (its last ``info``, return, length, the observation its last action saw).
    That observation is where the gripper was, within one step, when a touchdown ended the episode."""
    observation, _ = env.reset(seed=seed, options={"task": task})
    total, length = 0.0, 0
    while True:
        last_seen = observation
        observation, reward, terminated, truncated, info = env.step(act(observation))
        total += reward
        length += 1
        if terminated or truncated:
            return info, total, length, last_seen


def play(env: KukaGraspEnv, task: Task, policy: str, seed: int) -> tuple[bool, float, int]:
    """One episode of a named policy: (success, return, length)."""
    info, total, length, _ = run_episode(env, task, episode_policy(policy, np.random.default_rng(seed)), seed)
    return bool(info["is_success"]), total, length


def play_chunk(env_id: str, task: Task, policy: str, seeds: list[int]) -> list[tuple[bool, float, int]]:
    env = make_kuka_env(env_id)
    try:
        return [play(env, task, policy, seed) for seed in seeds]
    finally:
        env.close()


def points(env_id: str) -> dict[str, Task]:
    """The family's easiest and hardest points, the book's hardest where it is a point of the family,
    and points in between: every parameter a share of the way from its easiest to its hardest value,
    then the hard family's placement, speed and alignment margin each alone at the book's hardest
    (``shaping`` changes the returns only, not whether a fixed policy succeeds)."""
    space = task_space_for(env_id)
    easiest, hardest = space.easiest(), space.hardest()
    named = {"easiest": easiest}
    for share in (0.25, 0.5, 0.75):
        named[f"all {share:.0%} of the way"] = {
            name: easiest[name] + share * (hardest[name] - easiest[name]) for name in space.names
        }
    if env_id in (HARD_ENV_ID, HARD_V1_ENV_ID):
        book = KUKA_HARD_BOOK_HARDEST
        named["book's hardest"] = book
        for share in (0.5, 1.0):
            named[f"book's hardest, obj_far={share:g}"] = {**book, "obj_far": share}
        for scale in (0.5, MOVE_SCALE_HARDEST):
            named[f"book's hardest, move_scale={scale:g}"] = {**book, "move_scale": scale}
        margin = hardest["align_margin"]
        named[f"book's hardest, align_margin={margin:g}"] = {**book, "align_margin": margin}
    named["hardest"] = hardest
    return named


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", choices=ENV_IDS, default=HARD_ENV_ID, help=f"task family (default {HARD_ENV_ID})")
    parser.add_argument("--episodes", type=int, default=1000, help="episodes per point and policy (default 1000)")
    parser.add_argument("--seed", type=int, default=0, help="episode i is seeded seed + i (default 0)")
    parser.add_argument("--policies", nargs="+", choices=POLICIES, default=list(POLICIES))
    parser.add_argument("--points", nargs="+", help="only these points (default: all; names as printed)")
    parser.add_argument("--processes", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()

    chosen = points(args.env)
    if args.points:
        unknown = sorted(set(args.points) - set(chosen))
        if unknown:
            parser.error(f"unknown point(s) {unknown}; known: {list(chosen)}")
        chosen = {name: chosen[name] for name in args.points}
    seeds = [args.seed + index for index in range(args.episodes)]
    chunks = [seeds[start : start + CHUNK] for start in range(0, len(seeds), CHUNK)]
    jobs = [(name, policy) for name in chosen for policy in args.policies]
    report = []
    with StoppablePool(max_workers=args.processes) as pool:
        futures = {
            (name, policy): [pool.submit(play_chunk, args.env, chosen[name], policy, chunk) for chunk in chunks]
            for name, policy in jobs
        }
        print(f"{args.env}, {args.episodes} episodes per point and policy, episode seeds {seeds[0]} to {seeds[-1]}")
        for (name, policy), parts in futures.items():
            episodes = [episode for part in parts for episode in pool.result(part)]
            successes = sum(success for success, _, _ in episodes)
            interval = wilson_interval(successes, len(episodes))
            mean_return = float(np.mean([total for _, total, _ in episodes]))
            mean_length = float(np.mean([length for _, _, length in episodes]))
            print(
                f"{name:32s} {policy:8s} success {interval.estimate:6.1%} [{interval.low:.1%}, {interval.high:.1%}]"
                f"  return {mean_return:6.2f}  length {mean_length:5.0f}",
                flush=True,
            )
            report.append(
                {
                    "point": name,
                    "task": chosen[name],
                    "policy": policy,
                    "episodes": len(episodes),
                    "successes": successes,
                    "success_rate": interval.to_dict(),
                    "mean_return": mean_return,
                    "mean_length": mean_length,
                }
            )
    if args.json is not None:
        args.json.write_text(json.dumps({"env": args.env, "seed": args.seed, "results": report}, indent=2) + "\n")


if __name__ == "__main__":
    main()
