"""``kuka-curriculum evaluate``: how good is a checkpoint, with error bars.

The deterministic policy plays a fixed number of seeded episodes on one task of the environment it
was trained on (the checkpoint records it; ``--task`` names a point of its task space); the figures
come from ``checkpoint_evaluation``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from learner.arguments import UsageError, positive_int
from learner.checkpoint_arguments import TASK_HELP, checkpoint_task, read_checkpoint
from learner.checkpoint_evaluation import available_cpus, evaluate_checkpoint
from learner.json_file import write_json


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
    try:
        result = evaluate_checkpoint(checkpoint, task, args.episodes, args.seed, args.processes, args.max_episode_steps)
    except KeyboardInterrupt:
        print("kuka-curriculum evaluate: stopped; nothing was written", file=sys.stderr)
        return 130
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
