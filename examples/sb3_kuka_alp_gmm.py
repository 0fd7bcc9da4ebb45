"""Stable-Baselines3 PPO on KukaGrasp-v0, each episode's task chosen by ALP-GMM (or --teacher) on the teacher service.

Start a teacher, then train (the dashboard URL is printed first):

    .venv/bin/kuka-curriculum serve --port 8000 &
    .venv/bin/python examples/sb3_kuka_alp_gmm.py --total-steps 500000
    .venv/bin/python examples/sb3_kuka_alp_gmm.py --teacher manual --teacher-param step_back_below=0

``--teacher`` picks any kind the service offers and ``--teacher-param NAME=VALUE`` sets one of its
parameters on top of the KUKA defaults that ``kuka-curriculum train`` uses.

Each SubprocVecEnv worker wraps its environment in ``CurriculumWrapper``, which takes the tasks
and reports the returns, and in SB3's ``Monitor``, which writes every episode, with its task id, to
``LOG_DIR/env-N.monitor.csv``. When the service requires a token (``KC_TEACHER_TOKEN``), export the
same variable here.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import gymnasium
from stable_baselines3 import PPO
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import SubprocVecEnv

from common.client.curriculum_wrapper import CurriculumRegistration, CurriculumWrapper
from common.client.teacher_client import TeacherClient
from common.families.kuka import kuka_teacher_params
from common.kuka import ENV_ID
from common.kuka.task_space import KUKA_TASK_SPACE
from learner.commands.arguments import add_teacher_flags


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--teacher-url", default="http://127.0.0.1:8000", help="a running `kuka-curriculum serve`")
    parser.add_argument("--curriculum", help="created on first use (default: kuka-sb3-TEACHER)")
    add_teacher_flags(parser)
    parser.add_argument("--total-steps", type=int, default=500_000, help="environment steps, all envs together")
    parser.add_argument("--envs", type=int, default=2, help="SubprocVecEnv workers, one process each")
    parser.add_argument("--n-steps", type=int, default=1024, help="rollout length per env between PPO updates")
    parser.add_argument("--max-episode-steps", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--log-dir", type=Path, help="Monitor files, model (default: runs/sb3-kuka-TEACHER)")
    args = parser.parse_args(argv)
    args.curriculum = args.curriculum or f"kuka-sb3-{args.teacher}"
    args.log_dir = args.log_dir or Path(f"runs/sb3-kuka-{args.teacher}")
    return args


def make_env(args: argparse.Namespace, rank: int) -> Callable[[], gymnasium.Env]:
    """Runs in the worker process: the wrapper makes its teacher client there."""

    def make() -> gymnasium.Env:
        kuka = gymnasium.make(ENV_ID, max_steps=args.max_episode_steps)
        params = kuka_teacher_params(args.teacher, dict(args.teacher_params))
        register = CurriculumRegistration(args.teacher, KUKA_TASK_SPACE, params=params)
        env = CurriculumWrapper(kuka, args.teacher_url, args.curriculum, register=register)
        return Monitor(env, str(args.log_dir / f"env-{rank}"), info_keywords=("task_id",))

    return make


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    args.log_dir.mkdir(parents=True, exist_ok=True)
    print(f"watch the curriculum at {args.teacher_url.rstrip('/')}/curricula/{args.curriculum}", flush=True)

    envs = SubprocVecEnv([make_env(args, rank) for rank in range(args.envs)])
    model = PPO(
        "MlpPolicy",
        envs,
        n_steps=args.n_steps,
        batch_size=256,
        gamma=0.999,
        gae_lambda=0.99,
        seed=args.seed,
        device="cpu",
        verbose=1,
    )
    model.learn(total_timesteps=args.total_steps)
    model.save(args.log_dir / "ppo_kuka")
    envs.close()  # each worker's wrapper delivers its last results here

    with TeacherClient(args.teacher_url, args.curriculum) as teacher:
        received = teacher.info().counters.results_received
    print(f"done: {model.num_timesteps} steps; the teacher holds {received} results of {args.curriculum!r}")


if __name__ == "__main__":
    main()
