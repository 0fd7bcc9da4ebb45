"""``kuka-curriculum render``: a video of a checkpoint's policy at work, for people, on any family.

Frames come from the environment's ``render()`` in ``rgb_array`` mode (pybullet's CPU renderer on KUKA, so it
works headless), small ones enlarged so the labels fit. Every frame is labelled with the episode, the step, the
return so far and, at the end, whether the episode succeeded; the last frame of an episode is held for a moment
so the outcome can be read. Episodes take the same seeds as ``kuka-curriculum evaluate``'s with the same
``--seed``, and the policy acts as there, so the film shows the first episodes of that evaluation.
"""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path
from typing import Any

import gymnasium as gym
import imageio.v3 as iio
import numpy as np
from PIL import Image, ImageDraw, ImageFont
from tqdm import tqdm

from common.client.task_space import Task
from common.families import family_for
from common.families.base import env_action
from common.kuka import ENV_ID
from common.levels import DEFAULT_LEVELS
from common.policy.actor_critic import InferencePolicy, PolicySnapshot
from learner.commands.arguments import UsageError, positive_int, run_command
from learner.commands.checkpoint_arguments import CHECKPOINT_HELP, TASK_HELP, checkpoint_task, read_checkpoint
from learner.core.policy import policy_snapshot

FRAMES_PER_SECOND = 30.0
"""The film's rate at most: an environment rendering faster (KUKA's 240 steps a second of physics) is filmed
one step in several, so it plays at its own speed."""
DEFAULT_RENDER_FPS = 10.0
"""Steps a second for an environment whose metadata names no ``render_fps``."""
MIN_FRAME_HEIGHT = 240
"""Smaller frames (a grid's few pixels) are enlarged, pixels kept sharp, to at least this height."""
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


def camera_frame(env: gym.Env[np.ndarray, Any]) -> np.ndarray:
    """``env.render()`` for an environment made with ``render_mode="rgb_array"``, enlarged when small."""
    frame: Any = env.render()
    if not isinstance(frame, np.ndarray) or frame.ndim != 3:
        raise UsageError(f"{env.spec.id if env.spec else env}: render() in rgb_array mode gave no RGB image")
    image: np.ndarray = np.ascontiguousarray(frame[..., :3], dtype=np.uint8)
    scale = -(-MIN_FRAME_HEIGHT // image.shape[0])
    return image.repeat(scale, axis=0).repeat(scale, axis=1) if scale > 1 else image


def steps_per_frame(env: gym.Env[np.ndarray, Any]) -> int:
    """One frame in this many steps plays the environment at its own speed within ``FRAMES_PER_SECOND``."""
    fps = float(env.metadata.get("render_fps") or DEFAULT_RENDER_FPS)
    return max(1, round(fps / FRAMES_PER_SECOND))


def film_episodes(
    snapshot: PolicySnapshot,
    task: Task,
    episodes: int,
    seed: int = 0,
    max_episode_steps: int = 1000,
    progress: bool = True,
    env_id: str = ENV_ID,
    levels: int = DEFAULT_LEVELS,
) -> tuple[list[np.ndarray], float]:
    """Labelled frames of ``episodes`` episodes of ``env_id`` on ``task`` (none: held-out levels), the policy
    acting as its family evaluates, and the film's frames per second."""
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    family = family_for(env_id)
    env = family.make_env(env_id, max_episode_steps, render_mode="rgb_array")
    policy = InferencePolicy(snapshot)
    every = steps_per_frame(env)
    fps = min(FRAMES_PER_SECOND, float(env.metadata.get("render_fps") or DEFAULT_RENDER_FPS))
    hold = round(HOLD_LAST_FRAME_S * fps)
    frames: list[np.ndarray] = []
    seeds = family.episode_seeds(env_id, levels, seed, episodes)
    try:
        for episode, episode_seed in enumerate(
            tqdm(seeds, desc="filming", unit="episode", disable=not progress), start=1
        ):
            policy.rng = np.random.default_rng(episode_seed)  # as evaluate draws a sampling policy's actions
            observation, _ = env.reset(seed=episode_seed, options={"task": task})
            step, episode_return, done, success = 0, 0.0, False, None
            frames.append(label_frame(camera_frame(env), episode, episodes, step, episode_return, success))
            while not done:
                action, _, _ = policy.act(observation[None], deterministic=family.deterministic_evaluation)
                observation, reward, terminated, truncated, info = env.step(env_action(env.action_space, action[0]))
                step += 1
                episode_return += float(reward)
                done = terminated or truncated
                if done:
                    success = bool(info.get("is_success", False))
                if done or step % every == 0:
                    frames.append(label_frame(camera_frame(env), episode, episodes, step, episode_return, success))
            frames.extend([frames[-1]] * hold)
    finally:
        env.close()  # type: ignore[no-untyped-call]  # gymnasium's Env.close is unannotated
    return frames, fps


def write_video(path: Path, frames: list[np.ndarray], fps: float = FRAMES_PER_SECOND) -> None:
    check_output(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        iio.imwrite(path, frames, duration=1000 / fps, loop=0)
    else:
        iio.imwrite(path, frames, plugin="FFMPEG", fps=fps)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "checkpoint",
        type=Path,
        metavar="CHECKPOINT",
        help=CHECKPOINT_HELP,
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
    frames, fps = film_episodes(
        policy_snapshot(checkpoint),
        task,
        args.episodes,
        args.seed,
        args.max_episode_steps or checkpoint.config.max_episode_steps,
        env_id=checkpoint.config.env,
        levels=checkpoint.config.levels,
    )
    write_video(args.out, frames, fps)
    print(args.out)
    return 0
