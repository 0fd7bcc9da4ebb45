"""``kuka-curriculum train``: the whole training job from one command.

It wires the parts together and owns everything a person sees: the run directory, the teacher
service (started here unless ``--teacher-url`` names one), the Ray connection, the progress bar,
and Ctrl-C or SIGTERM (the first: finish the iteration, checkpoint and stop; a second: stop now).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from pydantic import SecretStr

from learner.commands.arguments import (
    UsageError,
    add_override_flags,
    non_negative_int,
    positive_int,
    run_command,
    teacher_kind,
    unit_fraction,
)
from learner.commands.config_file import CONFIG_HELP, config_path, read_config_file
from learner.commands.training_flags import add_training_flags
from learner.core.config import TEACHERS, TrainConfig
from learner.job.session import (
    PUBLIC_URL_VARIABLE,
    check_ray_reachable,
    connect_ray,
    curriculum_name,
    launch_teacher,
    register_curriculum,
    token_from_environment,
)

DEFAULTS = TrainConfig()
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""Ctrl-C, and what ``docker stop`` and process managers send: both stop after a checkpoint, and a run
stopped before its budget exits 128 + the signal's number (130, 143), as a shell reports a signal."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    run = parser.add_argument_group("run")
    run.add_argument(
        "--config",
        type=config_path,
        metavar="FILE_OR_RECIPE",
        help=f"{CONFIG_HELP}; flags given override it",
    )
    run.add_argument(
        "--teacher",
        type=teacher_kind,
        metavar="KIND",
        help=f"curriculum teacher, a kind of the service: {', '.join(TEACHERS)} (default {DEFAULTS.teacher}); "
        "`GET /api/v1/teachers` lists a running service's kinds and which task spaces each takes",
    )
    run.add_argument(
        "--total-steps", type=positive_int, help=f"environment steps to train for (default {DEFAULTS.total_steps:_})"
    )
    run.add_argument(
        "--seed", type=int, help=f"seed for the network, environments and teacher (default {DEFAULTS.seed})"
    )
    run.add_argument(
        "--eval-every",
        type=non_negative_int,
        help=f"iterations between evaluations on the hardest task, 0 for none (default {DEFAULTS.eval_every})",
    )
    run.add_argument(
        "--eval-episodes", type=positive_int, help=f"episodes per evaluation (default {DEFAULTS.eval_episodes})"
    )
    run.add_argument(
        "--edge-placement-share",
        type=unit_fraction,
        help="a hard KUKA family's training placements: the share of far points drawn beyond the arm's x clamp "
        f"only; evaluations keep the task's draw (default {DEFAULTS.edge_placement_share})",
    )
    add_override_flags(run, "for this run")
    add_training_flags(run, defaults_given=False, level_families=True)
    where = parser.add_argument_group("where")
    where.add_argument("--run-dir", type=Path, help="run directory (default runs/<teacher>-<timestamp>)")
    resume = where.add_mutually_exclusive_group()
    resume.add_argument(
        "--resume",
        action="store_true",
        help="continue the run in --run-dir from its latest checkpoint; flags given override its saved settings",
    )
    resume.add_argument(
        "--resume-if-exists",
        action="store_true",
        help="like --resume when --run-dir holds a checkpoint, else start the run there "
        "(for a supervisor that restarts the learner, such as Docker Compose)",
    )
    where.add_argument("--teacher-url", help="a running teacher service (default: start one for this run)")
    where.add_argument(
        "--public-url",
        help=f"the teacher's address in the printed dashboard link, as your browser reaches it "
        f"(default: ${PUBLIC_URL_VARIABLE}, else the teacher's own URL)",
    )
    where.add_argument("--ray-address", help="a running Ray cluster, host:port (default: start a local one)")


_RUN_SETTINGS = (
    "teacher",
    "env",
    "levels",
    "total_steps",
    "workers",
    "envs_per_worker",
    "max_episode_steps",
    "seed",
    "checkpoint_every",
    "eval_every",
    "eval_episodes",
    "loop",
    "edge_placement_share",
    "policy_choice",
)
"""``TrainConfig`` fields settable by the flag of the same name."""


def _config_from(args: argparse.Namespace, base: TrainConfig) -> TrainConfig:
    """``base`` (the defaults, or a resumed run's saved config), then ``--config``'s file, then every flag given."""
    if args.config is not None:
        base = read_config_file(args.config).applied_to(base, teacher=args.teacher)
    overrides: dict[str, Any] = {name: getattr(args, name) for name in _RUN_SETTINGS if getattr(args, name) is not None}
    ppo_values = dict(args.ppo)
    if args.rollout_length is not None:
        ppo_values["rollout_length"] = args.rollout_length
    teacher_overrides = {**base.teacher_overrides, **dict(args.teacher_params)}
    return replace(base, **overrides, teacher_overrides=teacher_overrides, ppo=base.ppo.with_overrides(ppo_values))


def run(args: argparse.Namespace) -> int:
    return run_command("train", _train, args, "stopped at once; the run resumes from its last periodic checkpoint")


def _train(args: argparse.Namespace) -> int:
    from learner.core.checkpoint import latest_checkpoint, load_checkpoint
    from learner.core.policy import policy_spec_for  # here: it loads torch, which --help does not need

    token = token_from_environment()
    checkpoint = None
    if args.resume or args.resume_if_exists:
        if args.run_dir is None:
            flag = "--resume" if args.resume else "--resume-if-exists"
            raise UsageError(f"{flag} needs --run-dir, the run to continue")
        path = latest_checkpoint(args.run_dir)
        if path is not None:
            checkpoint = load_checkpoint(path)
            if checkpoint.evaluation_only:
                raise UsageError(
                    f"{path} is an evaluation-only checkpoint (an archived run's, its optimiser state left out): "
                    "evaluate and render read it, but training cannot resume from it"
                )
        elif args.resume:
            raise UsageError(f"--resume: no checkpoint in {args.run_dir / 'checkpoints'}")
    try:
        config = _config_from(args, checkpoint.config if checkpoint else DEFAULTS)
        config.family.check(config.env)  # a user's module:EnvId imports, registers and declares a task space
        policy_spec_for(config.env, config.ppo, config.levels)  # settings the network cannot take (an image's)
    except ValueError as error:
        raise UsageError(str(error)) from None
    if checkpoint is not None and config.ppo.critic_task_inputs != checkpoint.config.ppo.critic_task_inputs:
        raise UsageError(
            f"the run in {args.run_dir} has critic_task_inputs={checkpoint.config.ppo.critic_task_inputs}, which "
            "sizes its critic; it cannot change on --resume"
        )
    if checkpoint is not None and config.env != checkpoint.config.env:
        raise UsageError(
            f"the run in {args.run_dir} trains on {checkpoint.config.env}; "
            f"choose another --run-dir for a run on {config.env}"
        )
    run_dir = args.run_dir or Path("runs") / f"{config.teacher}-{time.strftime('%Y%m%d-%H%M%S')}"
    if checkpoint is None and latest_checkpoint(run_dir) is not None:
        raise UsageError(f"{run_dir} already holds a run; pass --resume to continue it or choose another --run-dir")

    if args.ray_address is not None:
        check_ray_reachable(args.ray_address)

    with contextlib.ExitStack() as stack:
        # The curriculum is registered before Ray starts, so parameters the teacher refuses stop the
        # command at once; a tune, which registers in each trial, starts Ray while its service starts.
        teacher_url = launch_teacher(args.teacher_url, run_dir, stack)()
        name = curriculum_name(run_dir)
        register_curriculum(teacher_url, name, config, token)
        public_url = (args.public_url or os.environ.get(PUBLIC_URL_VARIABLE) or teacher_url).rstrip("/")
        connect_ray(args.ray_address, config.workers, stack)
        code = _run_training(config, run_dir, teacher_url, f"{public_url}/curricula/{name}", name, token, checkpoint)
    if code == 0 and config.policy_choice == "validated":
        # after the workers and the teacher have stopped: the validation episodes take the machine
        from learner.evaluation.selection import choose_validated_policy

        choose_validated_policy(run_dir)
    return code


def _run_training(
    config: TrainConfig,
    run_dir: Path,
    teacher_url: str,
    dashboard_url: str,
    name: str,
    token: SecretStr | None,
    checkpoint: Any,
) -> int:
    from tqdm import tqdm

    from learner.core.trainer import IterationReport, Trainer
    from learner.job.teacher_status import TeacherStatus

    trainer = Trainer(
        config, run_dir, teacher_url, name, teacher_token=token, resume_from=checkpoint, actor_name_prefix=name
    )
    print(f"run directory: {run_dir}")
    print(f"dashboard:     {dashboard_url}")
    start = trainer.counters.steps
    if checkpoint is not None:
        print(f"resuming from {checkpoint.path} at step {start:_}")

    stopped_by: list[int] = []

    def on_stop_signal(signum: int, frame: Any) -> None:
        if trainer.stop_requested:
            raise KeyboardInterrupt
        stopped_by.append(signum)
        trainer.request_stop()
        progress.write("stopping after this iteration (Ctrl-C again to stop at once, without a final checkpoint)")

    def on_iteration(report: IterationReport) -> None:
        progress.update(report.counters.steps - progress.n)
        progress.set_postfix_str(
            f"mean reward {report.recent_reward:.2f} | success {report.recent_success_rate:.0%} | {status.summary}",
            refresh=False,
        )

    with (
        TeacherStatus(teacher_url, name) as status,
        tqdm(
            total=config.total_steps, initial=start, unit="step", unit_scale=True, dynamic_ncols=True, smoothing=0.1
        ) as progress,
    ):
        previous = {signum: signal.signal(signum, on_stop_signal) for signum in STOP_SIGNALS}
        try:
            final = trainer.run(on_iteration)
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)
    unfinished = bool(stopped_by) and trainer.counters.steps < config.total_steps
    if unfinished:
        print(f"stopped at step {trainer.counters.steps:_} of {config.total_steps:_}; --resume continues the run")
    print(f"final checkpoint: {final}")
    # A run stopped early is not done: a script, or a restart policy such as Compose's on-failure, must see that.
    return 128 + stopped_by[0] if unfinished else 0
