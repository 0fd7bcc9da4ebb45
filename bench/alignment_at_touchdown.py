"""How square to the block the fingers touch down in the lifts a policy makes: how many of its lifts a
given ``align_margin`` would count. It is the measurement behind ``KukaGraspHard-v1``'s margin.

Each policy plays the family's hardest point with ``align_margin`` 90, so every lift counts and the
episode's last ``info`` gives the fingers' angle from square at touchdown; the margin does not enter the
observation, so a policy plays exactly as it would under any margin. A policy is one of
``bench/task_hardness.py``'s fixed ones (``zero``, ``random``, ``drift``, ``scripted``) or a checkpoint
(a ``.pt`` file or a run directory: its latest checkpoint, played deterministically, as ``evaluate`` does).

    .venv/bin/python bench/alignment_at_touchdown.py drift scripted \\
        benchmarks/bakeoff-hard/bakeoff/runs/currot-seed0 --episodes 1000 --seed 30000 --processes 2

Prints, per policy, the lifts and how many of them each margin counts (Wilson 95% intervals over the
episodes), and the quartiles of the touchdown angle over the lifts. Then, per policy, where the episodes
without a lift went: how many never touched down, and how far from the block the others touched down
(the block's x and y in the gripper's frame a step before touchdown, measured from the median over every
lift played here, where a grasp that holds the block puts it).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: the checkout's packages
from bench.task_hardness import CHUNK, POLICIES, Policy, episode_policy  # noqa: E402
from common.client.task_space import Task  # noqa: E402
from common.kuka import HARD_ENV_ID, HARD_V1_ENV_ID  # noqa: E402
from common.kuka.diagnostics import play_episode  # noqa: E402
from common.kuka.env import make_kuka_env  # noqa: E402
from common.kuka.task_space import ALIGN_MARGIN_ANY, task_space_for  # noqa: E402
from common.policy.actor_critic import InferencePolicy  # noqa: E402
from learner.commands.checkpoint_arguments import read_checkpoint  # noqa: E402
from learner.core.policy import policy_snapshot  # noqa: E402
from learner.evaluation.process_pool import StoppablePool  # noqa: E402
from learner.evaluation.stats import wilson_interval  # noqa: E402

MARGINS = (8.0, 5.0, 3.0, 2.0, 1.0)
"""Margins (degrees) to count the lifts under: v0's hardest 8, v1's 2, and around them."""

MISS_CM = (1.0, 2.0, 4.0)
"""Distances (cm) from where lifts hold the block: how many touchdowns without a lift lay farther."""

Touchdown = tuple[bool, float, float, float]
"""One episode: whether the block was lifted, the fingers' angle from square at touchdown, and the block's x
and y (metres) in the gripper's frame a step before touchdown (each NaN if the episode ended without
touching the tray), as ``common.kuka.diagnostics`` records them."""


def play_chunk(env_id: str, task: Task, policy: str, seeds: list[int]) -> list[Touchdown]:
    """Episodes of one policy, seeded ``seeds``; a policy not in ``POLICIES`` is a checkpoint path."""
    torch.set_num_threads(1)
    env = make_kuka_env(env_id)
    network = None if policy in POLICIES else InferencePolicy(policy_snapshot(read_checkpoint(Path(policy))))

    def deterministic(observation: np.ndarray) -> np.ndarray:
        assert network is not None
        action: np.ndarray = np.clip(network.act(observation[None], deterministic=True)[0][0], -1.0, 1.0)
        return action

    episodes = []
    try:
        for seed in seeds:
            act: Policy = deterministic if network else episode_policy(policy, np.random.default_rng(seed))
            played = play_episode(env, task, act, seed)
            touchdown = played.diagnostics
            measured = (touchdown.off_square_degrees, touchdown.touchdown_block_x, touchdown.touchdown_block_y)
            angle, block_x, block_y = (np.nan if value is None else value for value in measured)
            episodes.append((played.success, angle, block_x, block_y))
    finally:
        env.close()
    return episodes


def summarise(policy: str, episodes: list[Touchdown]) -> tuple[str, dict[str, Any]]:
    """A printed row and a JSON record: the lifts and, for each margin, the lifts it would count."""
    angles = np.array([angle for lifted, angle, _, _ in episodes if lifted])
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


def summarise_misses(policy: str, episodes: list[Touchdown], held_at: np.ndarray) -> tuple[str, dict[str, Any]]:
    """A printed row and a JSON record: the episodes without a lift, those that never touched down, and
    for the touchdowns without a lift how far (cm) the block lay from ``held_at``, where lifts hold it."""
    misses = [(angle, np.array([x, y])) for lifted, angle, x, y in episodes if not lifted]
    offsets_cm = np.array([100.0 * np.linalg.norm(xy - held_at) for angle, xy in misses if not np.isnan(angle)])
    no_touchdown = sum(1 for angle, _ in misses if np.isnan(angle))
    beyond = {cm: int(np.sum(offsets_cm > cm)) for cm in MISS_CM}
    quartiles = [round(float(cm), 1) for cm in np.quantile(offsets_cm, [0.25, 0.5, 0.75])] if offsets_cm.size else None
    cells = "  ".join(f"{count / len(episodes):9.1%}" for count in beyond.values())
    row = (
        f"{policy[-40:]:40s} {len(misses) / len(episodes):6.1%}  {no_touchdown / len(episodes):11.1%}  {cells}"
        f"   offset quartiles (cm) {quartiles}"
    )
    record = {
        "policy": policy,
        "episodes_without_lift": len(misses),
        "without_touchdown": no_touchdown,
        "touchdowns_farther_than_cm": {f"{cm:g}": count for cm, count in beyond.items()},
        "touchdown_offset_quartiles_cm": quartiles,
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
    records: dict[str, dict[str, Any]] = {}
    with StoppablePool(max_workers=args.processes) as pool:
        futures = {
            policy: [pool.submit(play_chunk, args.env, task, policy, chunk) for chunk in chunks]
            for policy in args.policies
        }
        played = {}
        for policy, parts in futures.items():
            played[policy] = [episode for part in parts for episode in pool.result(part)]
            row, records[policy] = summarise(policy, played[policy])
            print(row, flush=True)
    held = np.array([[x, y] for episodes in played.values() for lifted, _, x, y in episodes if lifted])
    if not held.size:
        print("no lifts, so no place where a lift holds the block to measure the misses from")
    else:
        held_at = np.median(held, axis=0)
        print(
            f"\nwithout a lift; touchdowns farther than each distance from where lifts hold the block "
            f"({100 * held_at[0]:.1f}, {100 * held_at[1]:.1f}) cm in the gripper's frame"
        )
        print(f"{'policy':40s} misses  no touchdown  " + "  ".join(f"   > {cm:g} cm" for cm in MISS_CM))
        for policy, episodes in played.items():
            row, records[policy]["misses"] = summarise_misses(policy, episodes, held_at)
            print(row, flush=True)
    if args.json is not None:
        args.json.write_text(
            json.dumps({"env": args.env, "task": task, "seed": args.seed, "results": list(records.values())}, indent=2)
            + "\n"
        )


if __name__ == "__main__":
    main()
