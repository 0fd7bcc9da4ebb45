"""Stable-Baselines3 PPO on MiniGrid levels, with the teacher service's PLR choosing each episode's level.

A level is the environment's reset seed, drawn from a fixed training set (``--levels`` of them): the
curriculum's task space is one integer parameter, ``level``. ``ResetSeedAsLevel`` resets MiniGrid
with the task's level as its seed, and ``PositiveValueLossScores``, a callback, sends each episode's
score once PPO knows its advantages: robust PLR's positive value loss, the mean over the episode's
steps of max(GAE advantage, 0) (the PLR paper's value_l1 takes the mean of |GAE advantage| instead).
Without ``--scores`` the wrapper reports at once and the PLR teacher scores a level by the gap between its
return and the level's previous return instead.

    .venv/bin/kuka-curriculum serve --port 8000 &
    .venv/bin/python examples/sb3_minigrid_plr.py --total-steps 200000
    .venv/bin/python examples/sb3_minigrid_plr.py --teacher random        # the uniform baseline

At the end it plays ``--eval-episodes`` held-out levels (seeds from 1,000,000, outside the training set)
and prints their success rate. When the service requires a token (``KC_TEACHER_TOKEN``), export it here.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium
import minigrid  # noqa: F401  # registers the MiniGrid environments
import numpy as np
from gymnasium.wrappers import FlattenObservation
from minigrid.wrappers import ImgObsWrapper
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import DummyVecEnv

from common.client.curriculum_wrapper import CurriculumRegistration, CurriculumWrapper
from common.client.task_space import Parameter, TaskSpace
from common.client.teacher_client import TeacherClient
from learner.commands.arguments import add_teacher_flags

HELD_OUT_FIRST_SEED = 1_000_000


def level_space(levels: int) -> TaskSpace:
    return TaskSpace([Parameter("level", 0, levels - 1, type="integer", doc="MiniGrid's reset seed")])


class ResetSeedAsLevel(gymnasium.Wrapper[Any, Any, Any, Any]):
    """Resets the environment with the task's ``level`` as its seed (the task comes in ``options``, as
    ``CurriculumWrapper`` passes it), and says whether the episode reached the goal (``is_success``)."""

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        task = (options or {}).get("task")
        return self.env.reset(seed=int(task["level"]) if task is not None else seed)

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            info = {**info, "is_success": float(reward) > 0}
        return observation, reward, terminated, truncated, info


def minigrid_env(env_id: str) -> gymnasium.Env[Any, Any]:
    """The environment's image (7 x 7 x 3 around the agent), flattened for an MLP policy."""
    return ResetSeedAsLevel(FlattenObservation(ImgObsWrapper(gymnasium.make(env_id))))


class PositiveValueLossScores(BaseCallback):
    """After each rollout, each environment's episodes that ended in it get their score: the mean over
    the episode's steps of max(advantage, 0), an episode begun in an earlier rollout counted from its
    first step. The scores go to the wrapper of each environment in the order its episodes ended."""

    def __init__(self) -> None:
        super().__init__()
        self._carried: dict[int, tuple[float, int]] = {}
        """Per environment, the positive advantages summed and the steps of its unfinished episode."""

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        buffer = self.model.rollout_buffer
        positive = np.maximum(buffer.advantages, 0.0)
        starts = buffer.episode_starts
        ended_last = self.locals["dones"]
        for env_index in range(positive.shape[1]):
            total, steps = self._carried.get(env_index, (0.0, 0))
            scores = []
            for step in range(positive.shape[0]):
                if starts[step, env_index] and steps:
                    scores.append(total / steps)
                    total, steps = 0.0, 0
                total, steps = total + float(positive[step, env_index]), steps + 1
            if ended_last[env_index]:
                scores.append(total / steps)
                total, steps = 0.0, 0
            self._carried[env_index] = (total, steps)
            self.training_env.env_method("report_scores", scores, indices=[env_index])


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--teacher-url", default="http://127.0.0.1:8000", help="a running `kuka-curriculum serve`")
    parser.add_argument("--curriculum", help="created on first use (default: minigrid-TEACHER)")
    add_teacher_flags(parser)
    parser.set_defaults(teacher="plr")
    parser.add_argument("--env", default="MiniGrid-DoorKey-5x5-v0", help="a MiniGrid environment id")
    parser.add_argument("--levels", type=int, default=200, help="training levels: reset seeds 0 to LEVELS - 1")
    parser.add_argument("--scores", action=argparse.BooleanOptionalAction, default=True, help="send PLR scores")
    parser.add_argument("--total-steps", type=int, default=200_000)
    parser.add_argument("--envs", type=int, default=4, help="environments in this process (one teacher client)")
    parser.add_argument("--eval-episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--log-dir", type=Path, help="the model (default: runs/sb3-minigrid-TEACHER)")
    args = parser.parse_args(argv)
    if not 1 <= args.levels <= 10_000:
        parser.error("--levels must be between 1 and 10000 (the level kinds' cap)")
    args.curriculum = args.curriculum or f"minigrid-{args.teacher}"
    args.log_dir = args.log_dir or Path(f"runs/sb3-minigrid-{args.teacher}")
    return args


def make_env(args: argparse.Namespace) -> Callable[[], gymnasium.Env[Any, Any]]:
    def make() -> gymnasium.Env[Any, Any]:
        register = CurriculumRegistration(args.teacher, level_space(args.levels), params=dict(args.teacher_params))
        return CurriculumWrapper(
            minigrid_env(args.env),
            args.teacher_url,
            args.curriculum,
            register=register,
            scores_from_learner=args.scores,
        )

    return make


def held_out_success(model: PPO, env_id: str, episodes: int) -> float:
    """The share of ``episodes`` levels from outside the training set that the policy solves."""
    env = minigrid_env(env_id)
    solved = 0
    for episode in range(episodes):
        observation, _ = env.reset(seed=HELD_OUT_FIRST_SEED + episode)
        done, info = False, {}
        while not done:
            action, _ = model.predict(observation, deterministic=False)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        solved += bool(info.get("is_success"))
    env.close()
    return solved / max(episodes, 1)


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    args.log_dir.mkdir(parents=True, exist_ok=True)
    print(f"watch the curriculum at {args.teacher_url.rstrip('/')}/curricula/{args.curriculum}", flush=True)

    envs = DummyVecEnv([make_env(args) for _ in range(args.envs)])
    model = PPO("MlpPolicy", envs, n_steps=256, batch_size=256, ent_coef=0.01, seed=args.seed, device="cpu", verbose=0)
    model.learn(total_timesteps=args.total_steps, callback=PositiveValueLossScores() if args.scores else None)
    model.save(args.log_dir / "ppo_minigrid")
    envs.close()

    success = held_out_success(model, args.env, args.eval_episodes)
    with TeacherClient(args.teacher_url, args.curriculum) as teacher:
        received = teacher.info().counters.results_received
    print(
        f"done: {model.num_timesteps} steps; held-out success {success:.2f} on {args.eval_episodes} levels; "
        f"the teacher holds {received} results of {args.curriculum!r}"
    )


if __name__ == "__main__":
    main()
