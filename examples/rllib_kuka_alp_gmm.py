"""RLlib PPO on KukaGrasp-v0 with several env runners, each episode's task chosen by ALP-GMM (or
--teacher) on the teacher service.

Start a teacher, then train (the dashboard URL is printed first):

    .venv/bin/kuka-curriculum serve --port 8000 &
    .venv/bin/python examples/rllib_kuka_alp_gmm.py --env-runners 2 --total-steps 500000

Every env runner is a Ray actor that makes its environments with ``make_env``; the wrapper in each
one makes its own teacher client, and when RLlib stops its env runners, closing their environments
delivers the last results. ``--ray-address`` joins a running Ray cluster instead of starting one.
When the service requires a token (``KC_TEACHER_TOKEN``), export the same variable here: the job's
``runtime_env`` passes it on to the env runners. ``--teacher`` picks any kind the service offers
and ``--teacher-param NAME=VALUE`` sets one of its parameters on top of the KUKA defaults.
"""

from __future__ import annotations

import argparse
import json
import os
from typing import Any

import gymnasium
import ray
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.utils.metrics import (
    ENV_RUNNER_RESULTS,
    EPISODE_RETURN_MEAN,
    NUM_ENV_STEPS_SAMPLED_LIFETIME,
    NUM_EPISODES_LIFETIME,
)
from ray.tune.registry import register_env

from common.client.curriculum_wrapper import TOKEN_VARIABLE, CurriculumRegistration, CurriculumWrapper
from common.client.teacher_client import TeacherClient
from common.families.kuka import kuka_teacher_params
from common.kuka import ENV_ID
from common.kuka.task_space import KUKA_TASK_SPACE
from learner.commands.arguments import add_teacher_flags

ENV_NAME = "kuka-grasp-curriculum"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--teacher-url", default="http://127.0.0.1:8000", help="a running `kuka-curriculum serve`")
    parser.add_argument("--curriculum", help="created on first use (default: kuka-rllib-TEACHER)")
    add_teacher_flags(parser)
    parser.add_argument("--total-steps", type=int, default=500_000, help="environment steps, all env runners together")
    parser.add_argument("--env-runners", type=int, default=2, help="Ray actors sampling in parallel")
    parser.add_argument("--batch-steps", type=int, default=4000, help="environment steps per PPO update")
    parser.add_argument("--max-episode-steps", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--ray-address", help="a running Ray cluster (default: start a local one)")
    args = parser.parse_args(argv)
    args.curriculum = args.curriculum or f"kuka-rllib-{args.teacher}"
    return args


def make_env(config: dict[str, Any]) -> gymnasium.Env:
    """Called by RLlib in each env runner with the ``env_config`` below. Ray sends this function by
    value, so an env runner has not imported ``common.kuka``, which registers the KUKA ids: import it."""
    import common.kuka  # noqa: F401

    kuka = gymnasium.make(ENV_ID, max_steps=config["max_episode_steps"])
    params = kuka_teacher_params(config["teacher"], dict(config["teacher_params"]))
    register = CurriculumRegistration(config["teacher"], KUKA_TASK_SPACE, params=params)
    return CurriculumWrapper(kuka, config["teacher_url"], config["curriculum"], register=register)


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    print(f"watch the curriculum at {args.teacher_url.rstrip('/')}/curricula/{args.curriculum}", flush=True)
    # The env runners of a running cluster do not see this shell's variables: hand them the token.
    token = os.environ.get(TOKEN_VARIABLE)
    runtime_env = {"env_vars": {TOKEN_VARIABLE: token}} if token else None
    if args.ray_address:
        ray.init(address=args.ray_address, runtime_env=runtime_env)
    else:
        ray.init(include_dashboard=False, runtime_env=runtime_env)
    register_env(ENV_NAME, make_env)
    env_config = {
        "teacher_url": args.teacher_url,
        "curriculum": args.curriculum,
        "teacher": args.teacher,
        "teacher_params": args.teacher_params,
        "max_episode_steps": args.max_episode_steps,
    }
    config = (
        PPOConfig()
        .environment(ENV_NAME, env_config=env_config)
        .env_runners(num_env_runners=args.env_runners, num_envs_per_env_runner=1)
        .training(
            train_batch_size_per_learner=args.batch_steps,
            minibatch_size=min(256, args.batch_steps),
            num_epochs=10,
            gamma=0.999,
            lambda_=0.99,
            lr=3e-4,
        )
        .debugging(seed=args.seed)
    )
    algorithm = config.build_algo()
    steps = episodes = 0
    while steps < args.total_steps:
        sampled = algorithm.train()[ENV_RUNNER_RESULTS]
        steps = int(sampled[NUM_ENV_STEPS_SAMPLED_LIFETIME])
        episodes = int(sampled.get(NUM_EPISODES_LIFETIME, 0))
        mean_return = sampled.get(EPISODE_RETURN_MEAN, float("nan"))
        print(f"steps {steps:>9}  episodes {episodes:>6}  mean return {mean_return:7.2f}", flush=True)
    algorithm.stop()  # closes every env runner's environments, which delivers their last results
    ray.shutdown()

    with TeacherClient(args.teacher_url, args.curriculum) as teacher:
        received = teacher.info().counters.results_received
    print(json.dumps({"env_steps": steps, "episodes": episodes, "results_received": received}))


if __name__ == "__main__":
    main()
