"""``kuka-curriculum control``: drive the grasp environment by hand in pybullet's window.

Sliders steer the gripper's x/y and the wrist (and, with ``--mode free``, its height and fingers); the
terminal shows the observation, the reward and each episode's outcome (``common.kuka.manual_control``).
The window needs a display: on a machine without one, run it under ``xvfb-run``.
"""

from __future__ import annotations

import argparse
import os
import sys

from common.kuka import ENV_ID, ENV_IDS
from common.kuka.bullet import native_output_silenced
from common.kuka.env import TIME_STEP, make_kuka_env
from common.kuka.manual_control import ManualControl, Mode, Report, SliderPanel, describe, drive
from common.kuka.task_space import task_space_for
from learner.commands.arguments import UsageError, positive_int, run_command
from learner.commands.checkpoint_arguments import parse_task


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", choices=ENV_IDS, default=ENV_ID, help="environment to drive")
    parser.add_argument(
        "--task",
        nargs="+",
        default=["hardest"],
        metavar="ITEM",
        help="'hardest' (the default), 'easiest', or NAME=VALUE items over the hardest task (after 'easiest', over "
        "the easiest one), e.g. '--task easiest jp2=1.0' or '--task rnd_obj_x=0,rnd_obj_y=0'; the names are the "
        "environment's task space's",
    )
    parser.add_argument(
        "--mode",
        choices=[mode.value for mode in Mode],
        default=Mode.GYM.value,
        help="gym: the environment lowers the arm and grasps, you steer x/y and the wrist; "
        "free: you also drive the height and the fingers (no reward: the environment's rules are off)",
    )
    parser.add_argument(
        "--steps", type=positive_int, default=None, help="stop after this many steps (default: when the window closes)"
    )
    parser.add_argument(
        "--print-every", type=positive_int, default=24, help="print every Nth step and every outcome (24: 10 a second)"
    )
    parser.add_argument("--seed", type=int, default=None, help="seed of the block placements")


def run(args: argparse.Namespace) -> int:
    return run_command("control", _control, args, "stopped")


def _control(args: argparse.Namespace) -> int:
    try:
        task = parse_task(",".join(args.task), task_space_for(args.env))
    except ValueError as error:
        raise UsageError(f"--task: {error}") from None
    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
        raise UsageError("pybullet's window needs a display and DISPLAY is not set; run it under xvfb-run to try it")
    mode = Mode(args.mode)
    env = make_kuka_env(args.env, task=task, window=True)
    try:
        control = ManualControl(env, mode, seed=args.seed)
        panel = SliderPanel(env, mode)
        print(f"{args.env}, {mode.value} mode, task {task}", flush=True)

        def show(report: Report) -> None:
            if report.outcome is not None or report.step % args.print_every == 0:
                print(describe(report), flush=True)

        done = drive(control, panel, show, steps=args.steps, seconds_per_step=TIME_STEP)
        print(f"{done} steps over {control.episode + 1} episode(s)", flush=True)
    finally:
        with native_output_silenced():  # pybullet's window reports its threads stopping on the C streams
            env.close()
    return 0
