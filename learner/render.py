"""``kuka-curriculum render``: a video of a checkpoint's policy at work, for people.

Frames come from pybullet's CPU renderer, so it works headless. Every frame is labelled with the
episode, the step, the return so far and, at the end, whether the grasp succeeded; the last
frame of an episode is held for a moment so the outcome can be read. Episode ``i`` is seeded
``seed + i``, as in ``kuka-curriculum evaluate``, so the film shows the first episodes of the
evaluation with the same seed.
"""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from PIL import Image, ImageDraw, ImageFont
from tqdm import tqdm

from common.client.task_space import Task
from common.kuka import ENV_ID
from common.kuka.env import KukaGraspEnv, make_kuka_env
from common.policy.actor_critic import InferencePolicy, PolicySnapshot
from learner.arguments import UsageError, positive_int, run_command
from learner.checkpoint_arguments import TASK_HELP, checkpoint_task, read_checkpoint
from learner.core.kuka_policy import policy_snapshot

STEPS_PER_FRAME = 8
"""A step is 1/240 s of physics: one frame in eight plays at real speed (30 frames per second)."""
FRAMES_PER_SECOND = KukaGraspEnv.metadata["render_fps"] / STEPS_PER_FRAME
HOLD_LAST_FRAME_S = 1.0
FORMATS = (".gif", ".mp4")

BAND_COLOUR = (0, 0, 0, 150)
TEXT_COLOUR = (255, 255, 255)
SUCCESS_COLOUR = (90, 230, 90)
FAILURE_COLOUR = (255, 110, 90)


def check_output(path: Path) -> None:
    """Refuse an output the writer cannot produce before spending minutes filming."""
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise UsageError(f"--out must end in {' or '.join(FORMATS)}, got {path.name!r}")
    if suffix == ".mp4" and importlib.util.find_spec("imageio_ffmpeg") is None:
        raise UsageError(
            "writing .mp4 needs the imageio-ffmpeg package (pip install 'kuka-curriculum[video]'); "
            ".gif works without it"
        )


def label_frame(
    frame: np.ndarray, episode: int, episodes: int, step: int, episode_return: float, success: bool | None
) -> np.ndarray:
    """Draw the episode's progress on a band across the top; ``success`` is None while it runs."""
    image = Image.fromarray(frame).convert("RGBA")
    band = Image.new("RGBA", image.size, (0, 0, 0, 0))
    draw = ImageDraw.Draw(band)
    font = ImageFont.load_default(size=max(10, image.height // 18))
    assert isinstance(font, ImageFont.FreeTypeFont), "a sized default font needs Pillow built with FreeType"
    line_height = font.size + 4
    draw.rectangle((0, 0, image.width, 2 * line_height + 8), fill=BAND_COLOUR)
    draw.text((6, 4), f"episode {episode}/{episodes}   step {step}", font=font, fill=TEXT_COLOUR)
    draw.text((6, 4 + line_height), f"return {episode_return:+.2f}", font=font, fill=TEXT_COLOUR)
    if success is not None:
        outcome, colour = ("success", SUCCESS_COLOUR) if success else ("no grasp", FAILURE_COLOUR)
        width = draw.textlength(outcome, font=font)
        draw.text((image.width - width - 6, 4 + line_height), outcome, font=font, fill=colour)
    return np.asarray(Image.alpha_composite(image, band).convert("RGB"))


def camera_frame(env: KukaGraspEnv) -> np.ndarray:
    """``env.render()`` for an environment made with ``render_mode="rgb_array"``, which always renders."""
    frame = env.render()
    assert frame is not None, "the environment was made without render_mode='rgb_array'"
    return frame


def film_episodes(
    snapshot: PolicySnapshot,
    task: Task,
    episodes: int,
    seed: int = 0,
    max_episode_steps: int = 1000,
    progress: bool = True,
    env_id: str = ENV_ID,
) -> list[np.ndarray]:
    """Labelled frames of ``episodes`` deterministic episodes of ``env_id``, one frame per ``STEPS_PER_FRAME`` steps."""
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    env = make_kuka_env(env_id, render_mode="rgb_array", max_steps=max_episode_steps, task=task)
    policy = InferencePolicy(snapshot)
    low, high = env.action_space.low, env.action_space.high
    hold = round(HOLD_LAST_FRAME_S * FRAMES_PER_SECOND)
    frames: list[np.ndarray] = []
    try:
        for episode in tqdm(range(1, episodes + 1), desc="filming", unit="episode", disable=not progress):
            observation, _ = env.reset(seed=seed + episode - 1, options={"task": task})
            step, episode_return, done, success = 0, 0.0, False, None
            frames.append(label_frame(camera_frame(env), episode, episodes, step, episode_return, success))
            while not done:
                action, _, _ = policy.act(observation[None], deterministic=True)
                observation, reward, terminated, truncated, info = env.step(np.clip(action[0], low, high))
                step += 1
                episode_return += float(reward)
                done = terminated or truncated
                if done:
                    success = bool(info["is_success"])
                if done or step % STEPS_PER_FRAME == 0:
                    frames.append(label_frame(camera_frame(env), episode, episodes, step, episode_return, success))
            frames.extend([frames[-1]] * hold)
    finally:
        env.close()
    return frames


def write_video(path: Path, frames: list[np.ndarray]) -> None:
    check_output(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        iio.imwrite(path, frames, duration=1000 / FRAMES_PER_SECOND, loop=0)
    else:
        iio.imwrite(path, frames, plugin="FFMPEG", fps=FRAMES_PER_SECOND)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "checkpoint",
        type=Path,
        metavar="CHECKPOINT",
        help="a checkpoint file, or a run directory (its latest checkpoint)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="FILE.gif|FILE.mp4",
        help="the video to write (.mp4 needs imageio-ffmpeg)",
    )
    parser.add_argument("--episodes", type=positive_int, default=3, help="episodes to film (default 3)")
    parser.add_argument("--task", default="hardest", help=TASK_HELP)
    parser.add_argument("--seed", type=int, default=0, help="episode i is seeded seed + i, as in evaluate (default 0)")
    parser.add_argument(
        "--max-episode-steps",
        type=positive_int,
        help="episode step limit (default: the one the checkpoint was trained with)",
    )


def run(args: argparse.Namespace) -> int:
    return run_command("render", _render, args, "stopped")


def _render(args: argparse.Namespace) -> int:
    check_output(args.out)
    checkpoint = read_checkpoint(args.checkpoint)
    task = checkpoint_task(args.task, checkpoint)
    frames = film_episodes(
        policy_snapshot(checkpoint),
        task,
        args.episodes,
        args.seed,
        args.max_episode_steps or checkpoint.config.max_episode_steps,
        env_id=checkpoint.config.env,
    )
    write_video(args.out, frames)
    print(args.out)
    return 0
