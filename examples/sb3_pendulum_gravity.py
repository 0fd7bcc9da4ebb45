"""Stable-Baselines3 PPO on gymnasium's Pendulum-v1, with ALP-GMM choosing each episode's gravity and mass.

Pendulum knows nothing of tasks: ``apply_pendulum_task`` sets the physics from the task before each
reset, and the curriculum's own task space (``PENDULUM_TASK_SPACE``) is registered with the service
over HTTP by the wrapper. Any environment whose parameters can be set from Python works this way.

    .venv/bin/kuka-curriculum serve --port 8000 &
    .venv/bin/python examples/sb3_pendulum_gravity.py --total-steps 200000

When the service requires a token (``KC_TEACHER_TOKEN``), export the same variable here.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import gymnasium
from gymnasium.envs.classic_control.pendulum import PendulumEnv
from stable_baselines3 import PPO
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from common.curriculum_wrapper import CurriculumRegistration, CurriculumWrapper
from common.task_space import Parameter, Task, TaskSpace
from common.teacher_client import TeacherClient

PENDULUM_TASK_SPACE = TaskSpace(
    [
        Parameter("gravity", 2.0, 12.0, hardest=12.0, easiest=2.0, doc="m/s^2; Pendulum-v1's default is 10"),
        Parameter("mass", 0.5, 1.5, hardest=1.5, easiest=0.5, doc="kg; the motor's torque is capped at 2 N m"),
    ]
)
"""Light and in low gravity, the pendulum swings up with one push; heavy and in high gravity it must
be rocked up."""

ALP_GMM = CurriculumRegistration(
    "alp-gmm", PENDULUM_TASK_SPACE, params={"fit_rate": 100, "reward_range": [-1500.0, 0.0]}
)
"""A fit every 100 episodes (20,000 steps); an episode's return lies between about -1,500 and 0."""


def apply_pendulum_task(env: gymnasium.Env, task: Task) -> None:
    """Set the pendulum's physics for the next episode (read by every ``step``)."""
    pendulum = env.unwrapped
    assert isinstance(pendulum, PendulumEnv)
    pendulum.g = task["gravity"]
    pendulum.m = task["mass"]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--teacher-url", default="http://127.0.0.1:8000", help="a running `kuka-curriculum serve`")
    parser.add_argument("--curriculum", default="pendulum-alp-gmm", help="created on first use")
    parser.add_argument("--total-steps", type=int, default=200_000)
    parser.add_argument("--envs", type=int, default=4, help="environments in this process (one teacher client)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--log-dir", type=Path, default=Path("runs/sb3-pendulum-alp-gmm"), help="Monitor files, model")
    return parser.parse_args(argv)


def make_env(args: argparse.Namespace, rank: int) -> Callable[[], gymnasium.Env]:
    def make() -> gymnasium.Env:
        pendulum = gymnasium.make("Pendulum-v1")
        env = CurriculumWrapper(
            pendulum, args.teacher_url, args.curriculum, register=ALP_GMM, apply_task=apply_pendulum_task
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
