"""Stable-Baselines3 PPO on gymnasium's Pendulum-v1, with a curriculum teacher choosing each episode's gravity and mass.

Pendulum knows nothing of tasks: ``apply_pendulum_task`` sets the physics from the task before each
reset, and the curriculum's own task space (``PENDULUM_TASK_SPACE``) is registered with the service
over HTTP by the wrapper. Any environment whose parameters can be set from Python works this way.

    .venv/bin/kuka-curriculum serve --port 8000 &
    .venv/bin/python examples/sb3_pendulum_gravity.py --total-steps 200000
    .venv/bin/python examples/sb3_pendulum_gravity.py --teacher manual --teacher-param step_back_below=-900

``--teacher`` picks any kind the service offers (ALP-GMM by default) and ``--teacher-param`` sets
one of its parameters on top of ``PENDULUM_TEACHER_PARAMS``.

When the service requires a token (``KC_TEACHER_TOKEN``), export the same variable here.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium
from gymnasium.envs.classic_control.pendulum import PendulumEnv
from stable_baselines3 import PPO
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from common.client.curriculum_wrapper import CurriculumRegistration, CurriculumWrapper
from common.client.task_space import Parameter, Task, TaskSpace
from common.client.teacher_client import TeacherClient
from learner.commands.arguments import add_teacher_flags

PENDULUM_TASK_SPACE = TaskSpace(
    [
        Parameter("gravity", 2.0, 12.0, hardest=12.0, easiest=2.0, doc="m/s^2; Pendulum-v1's default is 10"),
        Parameter("mass", 0.5, 1.5, hardest=1.5, easiest=0.5, doc="kg; the motor's torque is capped at 2 N m"),
    ]
)
"""Light and in low gravity, the pendulum swings up with one push; heavy and in high gravity it must
be rocked up."""

PENDULUM_TEACHER_PARAMS: dict[str, dict[str, Any]] = {
    "alp-gmm": {"fit_rate": 100, "reward_range": [-1500.0, 0.0]},
    "manual": {"threshold": -400.0, "window": 20, "min_episodes": 20},
}
"""Pendulum's returns lie between about -1,500 and 0: ALP-GMM maps them onto [0, 1] and fits every
100 episodes (20,000 steps); the lesson plan moves on once 20 episodes average above -400 (a swing-up
that holds the pendulum upright for most of the episode). Other kinds start from their own defaults."""


def apply_pendulum_task(env: gymnasium.Env, task: Task) -> None:
    """Set the pendulum's physics for the next episode (read by every ``step``)."""
    pendulum = env.unwrapped
    assert isinstance(pendulum, PendulumEnv)
    pendulum.g = task["gravity"]
    pendulum.m = task["mass"]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--teacher-url", default="http://127.0.0.1:8000", help="a running `kuka-curriculum serve`")
    parser.add_argument("--curriculum", help="created on first use (default: pendulum-TEACHER)")
    add_teacher_flags(parser)
    parser.add_argument("--total-steps", type=int, default=200_000)
    parser.add_argument("--envs", type=int, default=4, help="environments in this process (one teacher client)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--log-dir", type=Path, help="Monitor files, model (default: runs/sb3-pendulum-TEACHER)")
    args = parser.parse_args(argv)
    args.curriculum = args.curriculum or f"pendulum-{args.teacher}"
    args.log_dir = args.log_dir or Path(f"runs/sb3-pendulum-{args.teacher}")
    return args


def registration(args: argparse.Namespace) -> CurriculumRegistration:
    """The curriculum to create if it does not exist: the chosen kind over the pendulum's space."""
    params = {**PENDULUM_TEACHER_PARAMS.get(args.teacher, {}), **dict(args.teacher_params)}
    return CurriculumRegistration(args.teacher, PENDULUM_TASK_SPACE, params=params)


def make_env(args: argparse.Namespace, rank: int) -> Callable[[], gymnasium.Env]:
    def make() -> gymnasium.Env:
        pendulum = gymnasium.make("Pendulum-v1")
        env = CurriculumWrapper(
            pendulum, args.teacher_url, args.curriculum, register=registration(args), apply_task=apply_pendulum_task
        )
        return Monitor(env, str(args.log_dir / f"env-{rank}"), info_keywords=("task_id",))

    return make


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    args.log_dir.mkdir(parents=True, exist_ok=True)
    print(f"watch the curriculum at {args.teacher_url.rstrip('/')}/curricula/{args.curriculum}", flush=True)

    envs = DummyVecEnv([make_env(args, rank) for rank in range(args.envs)])
    # Close to RL Zoo's PPO settings for Pendulum-v1, without its observation normalisation.
    model = PPO(
        "MlpPolicy",
        envs,
        n_steps=1024,
        gae_lambda=0.95,
        gamma=0.9,
        n_epochs=10,
        ent_coef=0.0,
        learning_rate=1e-3,
        clip_range=0.2,
        use_sde=True,
        sde_sample_freq=4,
        seed=args.seed,
        device="cpu",
        verbose=1,
    )
    model.learn(total_timesteps=args.total_steps)
    model.save(args.log_dir / "ppo_pendulum")
    envs.close()

    with TeacherClient(args.teacher_url, args.curriculum) as teacher:
        received = teacher.info().counters.results_received
    print(f"done: {model.num_timesteps} steps; the teacher holds {received} results of {args.curriculum!r}")


if __name__ == "__main__":
    main()
