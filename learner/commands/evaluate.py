"""``kuka-curriculum evaluate``: how good is a checkpoint, with error bars, and where it fails.

The policy plays a fixed number of seeded episodes on one task of the environment it was trained on (the
checkpoint records it, a user's ``module:EnvId`` included; ``--task`` names a point of its task space, by
default its evaluation task: the hardest, or held-out levels); the figures come from
``checkpoint_evaluation``. On a KUKA family each episode records where its block lay and how the gripper met
it, and the printout splits success by how far the block lay beyond the arm's reach.
``--scripted`` also plays the scripted controller on the same episodes, the yardstick a policy is read
against; without a checkpoint it plays alone, on ``--env``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from common.kuka import ENV_IDS, HARD_V1_ENV_ID
from common.kuka.task_space import task_space_for
from learner.commands.arguments import UsageError, positive_int, run_command
from learner.commands.checkpoint_arguments import (
    CHECKPOINT_HELP,
    TASK_HELP,
    checkpoint_task,
    parse_task,
    read_checkpoint,
)
from learner.core.json_file import write_json
from learner.evaluation.checkpoint_evaluation import (
    EvaluationResult,
    available_cpus,
    checkpoint_record,
    evaluate_checkpoint,
    evaluate_policy,
    scripted_record,
)
from learner.evaluation.episode_diagnostics import success_by_band
from learner.evaluation.selection import recorded_choice

DEFAULT_MAX_STEPS = 1000
"""The scripted controller's episode limit when no checkpoint gives one: the environments' default."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "checkpoint",
        type=Path,
        nargs="?",
        metavar="CHECKPOINT",
        help=f"{CHECKPOINT_HELP}; may be left out with --scripted",
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
    parser.add_argument(
        "--scripted",
        action="store_true",
        help="also play the hand-made scripted controller on the same episodes (alone without a checkpoint)",
    )
    parser.add_argument(
        "--env",
        choices=ENV_IDS,
        help=f"the environment for the scripted controller alone (default {HARD_V1_ENV_ID}); a checkpoint is "
        "evaluated on its own",
    )
    parser.add_argument("--json", type=Path, metavar="PATH", help="also write the results, per episode included, here")


def placement_line(result: EvaluationResult) -> str:
    """Success by placement band, one line: 'by placement: inside the clamp 72% (38), ...'; nothing where the
    episodes recorded no placements (a family other than KUKA's)."""
    if not result.diagnostics:
        return ""
    bands = success_by_band(result.diagnosed())
    return "\nby placement: " + ", ".join(f"{band.label} {band.cell()}" for band in bands)


def run(args: argparse.Namespace) -> int:
    return run_command("evaluate", _evaluate, args, "stopped; nothing was written")


def _evaluate(args: argparse.Namespace) -> int:
    if args.checkpoint is None:
        if not args.scripted:
            raise UsageError("give a CHECKPOINT, or --scripted for the scripted controller alone")
        env = args.env or HARD_V1_ENV_ID
        try:
            task = parse_task(args.task, task_space_for(env))
        except ValueError as error:
            raise UsageError(f"--task: {error}") from None
        scripted = evaluate_policy(
            None,
            task,
            args.episodes,
            args.seed,
            args.processes,
            args.max_episode_steps or DEFAULT_MAX_STEPS,
            env_id=env,
        )
        print(f"scripted controller: {scripted.summary()}{placement_line(scripted)}")
        if args.json is not None:
            write_json(args.json, scripted_record(scripted))
        return 0

    checkpoint = read_checkpoint(args.checkpoint)
    if args.env is not None and args.env != checkpoint.config.env:
        raise UsageError(f"--env {args.env}: the checkpoint was trained on {checkpoint.config.env}, where it is played")
    task = checkpoint_task(args.task, checkpoint)
    result = evaluate_checkpoint(checkpoint, task, args.episodes, args.seed, args.processes, args.max_episode_steps)
    validated = args.checkpoint.is_dir() and recorded_choice(args.checkpoint) is not None
    which = ", the run's validated policy" if validated else ""
    print(f"{checkpoint.path} ({checkpoint.config.teacher}, {checkpoint.counters.steps:_} steps{which})")
    print(f"{result.summary()}{placement_line(result)}")
    record = checkpoint_record(checkpoint, result)
    if args.scripted:
        steps = args.max_episode_steps or checkpoint.config.max_episode_steps
        try:
            checkpoint.config.family.scripted_controller(checkpoint.config.env)
        except ValueError as error:
            raise UsageError(f"--scripted: {error}") from None
        scripted = evaluate_policy(
            None, task, args.episodes, args.seed, args.processes, steps, env_id=checkpoint.config.env
        )
        print(f"scripted controller, the same episodes: {scripted.summary()}{placement_line(scripted)}")
        record["scripted"] = scripted_record(scripted)
    if args.json is not None:
        write_json(args.json, record)
    return 0
