"""How square to the block the fingers touch down in the lifts a policy makes: how many of its lifts a
given ``align_margin`` would count. It is the measurement behind ``KukaGraspHard-v1``'s margin.

Each policy plays the family's hardest point with ``align_margin`` 90, so every lift counts and the
episode's last ``info`` gives the fingers' angle from square at touchdown; the margin does not enter the
observation, so a policy plays exactly as it would under any margin. A policy is one of
``bench/task_hardness.py``'s fixed ones (``zero``, ``random``, ``drift``, ``scripted``) or a checkpoint
(a ``.pt`` file or a run directory: its latest checkpoint, played deterministically, as ``evaluate`` does).

    .venv/bin/python bench/alignment_at_touchdown.py drift scripted benchmarks/bakeoff-hard/bakeoff/runs/currot-seed0 \\
        --episodes 1000 --seed 30000 --processes 2

Prints, per policy, the lifts and how many of them each margin counts (Wilson 95% intervals over the
episodes), and the quartiles of the touchdown angle over the lifts.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch

# A sibling script (bench/ is the script's path, not a package).
from task_hardness import CHUNK, POLICIES, Policy, episode_policy, run_episode

from common.client.task_space import Task
from common.kuka import HARD_ENV_ID, HARD_V1_ENV_ID
from common.kuka.env import make_kuka_env
from common.kuka.task_space import ALIGN_MARGIN_ANY, task_space_for
from common.policy.actor_critic import InferencePolicy
from learner.checkpoint_arguments import read_checkpoint
from learner.kuka_policy import policy_snapshot
from learner.process_pool import StoppablePool
from learner.stats import wilson_interval

MARGINS = (8.0, 5.0, 3.0, 2.0, 1.0)
"""Margins (degrees) to count the lifts under: v0's hardest 8, v1's 2, and around them."""

Touchdown = tuple[bool, float]
"""One episode: whether the block was lifted, and the fingers' angle from square at touchdown (NaN if the
episode ended without touching the tray)."""


def play_chunk(env_id: str, task: Task, policy: str, seeds: list[int]) -> list[Touchdown]:
    """Episodes of one policy, seeded ``seeds``; a policy not in ``POLICIES`` is a checkpoint path."""
    torch.set_num_threads(1)
    env = make_kuka_env(env_id)
    network = None if policy in POLICIES else InferencePolicy(policy_snapshot(read_checkpoint(Path(policy))))

    def deterministic(observation: np.ndarray) -> np.ndarray:
        assert network is not None
        return np.clip(network.act(observation[None], deterministic=True)[0][0], -1.0, 1.0)

    episodes = []
    try:
        for seed in seeds:
            act: Policy = deterministic if network else episode_policy(policy, np.random.default_rng(seed))
            info, _, _ = run_episode(env, task, act, seed)
            episodes.append((bool(info["is_success"]), float(info.get("off_square_degrees", np.nan))))
    finally:
        env.close()
    return episodes


def summarise(policy: str, episodes: list[Touchdown]) -> tuple[str, dict[str, Any]]:
    """A printed row and a JSON record: the lifts and, for each margin, the lifts it would count."""
    angles = np.array([angle for lifted, angle in episodes if lifted])
    lifts = wilson_interval(len(angles), len(episodes))
    counted = {margin: wilson_interval(int(np.sum(angles <= margin)), len(episodes)) for margin in MARGINS}
    quartiles = [round(float(angle), 2) for angle in np.quantile(angles, [0.25, 0.5, 0.75])] if angles.size else None
    cells = "  ".join(f"{interval.estimate:9.1%}" for interval in counted.values())
    row = f"{policy[-40:]:40s} {lifts.estimate:6.1%}  {cells}   lift angle quartiles {quartiles}"
    record = {
        "policy": policy,
        "episodes": len(episodes),
        "lifts": lifts.to_dict(),
        "counted_by_margin": {f"{margin:g}": interval.to_dict() for margin, interval in counted.items()},
        "lift_angle_quartiles": quartiles,
    }
    return row, record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("policies", nargs="+", help=f"{', '.join(POLICIES)}, or a checkpoint or run directory")
    parser.add_argument("--env", choices=(HARD_ENV_ID, HARD_V1_ENV_ID), default=HARD_V1_ENV_ID, help="hard family")
    parser.add_argument("--episodes", type=int, default=1000, help="episodes per policy (default 1000)")
    parser.add_argument("--seed", type=int, default=30000, help="episode i is seeded seed + i (default 30000)")
    parser.add_argument("--processes", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()
    for policy in args.policies:
        if policy not in POLICIES and not Path(policy).exists():
            parser.error(f"{policy!r} is neither one of {', '.join(POLICIES)} nor a checkpoint or run directory")

    task = {**task_space_for(args.env).hardest(), "align_margin": ALIGN_MARGIN_ANY}
    seeds = [args.seed + index for index in range(args.episodes)]
    chunks = [seeds[start : start + CHUNK] for start in range(0, len(seeds), CHUNK)]
    print(f"{args.env} hardest point, align_margin {ALIGN_MARGIN_ANY:g}, episode seeds {seeds[0]} to {seeds[-1]}")
    print(f"{'policy':40s} lifts   " + "  ".join(f"<= {margin:g} deg" for margin in MARGINS))
    report = []
    with StoppablePool(max_workers=args.processes) as pool:
        futures = {
            policy: [pool.submit(play_chunk, args.env, task, policy, chunk) for chunk in chunks]
            for policy in args.policies
        }
        for policy, parts in futures.items():
            row, record = summarise(policy, [episode for part in parts for episode in part.result()])
            print(row, flush=True)
            report.append(record)
    if args.json is not None:
        args.json.write_text(
            json.dumps({"env": args.env, "task": task, "seed": args.seed, "results": report}, indent=2) + "\n"
        )


if __name__ == "__main__":
    main()
