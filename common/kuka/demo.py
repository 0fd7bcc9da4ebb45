"""``kuka-curriculum demo``: a short GIF of the KUKA grasp environment under random actions.

A quick look at the scene (arm, tray, block) without a display: frames come from pybullet's CPU
renderer. A step is 1/240 s of physics, so keeping one frame in eight plays at real speed.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import cast

import imageio.v3 as iio
import numpy as np
from tqdm import tqdm

from common.kuka.env import KukaGraspEnv
from common.kuka.task_space import KUKA_TASK_SPACE

STEPS_PER_FRAME = 8
FRAME_MS = 1000 * STEPS_PER_FRAME / KukaGraspEnv.metadata["render_fps"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=Path("runs/demo.gif"), help="where to write the GIF")
    parser.add_argument("--steps", type=int, default=800, help="environment steps to film (one frame per 8)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the block placement and the actions")
    parser.add_argument(
        "--task",
        choices=("hardest", "easiest"),
        default="hardest",
        help="curriculum anchor to film; 'easiest' usually ends in a grasp within 100 steps",
    )


def run(args: argparse.Namespace) -> int:
    if args.steps < 1:
        raise ValueError(f"--steps must be at least 1, got {args.steps}")
    task = KUKA_TASK_SPACE.hardest() if args.task == "hardest" else KUKA_TASK_SPACE.easiest()
    env = KukaGraspEnv(render_mode="rgb_array", task=task)
    env.action_space.seed(args.seed)
    env.reset(seed=args.seed)
    frames = [env.render()]
    for step in tqdm(range(1, args.steps + 1), desc="filming", unit="step"):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            frames.append(env.render())  # the end of the scripted grasp
            env.reset()
            frames.append(env.render())
        elif step % STEPS_PER_FRAME == 0:
            frames.append(env.render())
    env.close()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    # An rgb_array environment renders a frame every time; render() is None only without a render mode.
    iio.imwrite(args.out, cast(list[np.ndarray], frames), duration=FRAME_MS, loop=0)
    print(args.out)
    return 0
