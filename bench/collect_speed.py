"""How much of the machine's raw simulation speed survives distributed collection with the policy in the loop.

In one run: (1) the raw rate of one environment in one process with random actions, (2) the
sampling-phase rate of W rollout actors stepping their environments through the policy and
reporting every episode to a real teacher service, and (3) the whole-iteration rate (sampling
plus the PPO update and the weight broadcast), both from the real training loop. Prints the ratio
of (2) to W times (1).

Fair comparison: every episode plays the hardest task (the ``fixed`` teacher) in both, so the
share of time spent in resets and scripted grasps is the same; and the raw rate is measured in a
Ray worker process, before and after the training phase, so it runs at the same scheduling
priority as the rollout actors (Ray lowers its workers' priority) and sees the same machine load.

W times the one-process rate is what W free cores would give. On a machine shared with other
work they are not free, so the script also runs W raw processes at once and prints the ratio to
their total: that one isolates the pipeline's own overhead from the machine's load.

    .venv/bin/python bench/collect_speed.py --workers 2
"""

from __future__ import annotations

import argparse
import logging
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import ray

from common.client.teacher_client import TeacherClient
from common.kuka.env import KukaGraspEnv
from common.kuka.task_space import KUKA_TASK_SPACE
from learner.core.config import PPOConfig, TrainConfig
from learner.core.trainer import IterationReport, Trainer
from learner.job.session import curriculum_name
from learner.job.teacher_process import local_teacher_service

TEACHER = "fixed"
MEASURED_STEPS_PER_ENV = 5120
"""Every environment starts together and plays ~815-step episodes, each ending in a slow scripted
grasp; a window of one episode per environment would hold too few or too many grasps."""


@ray.remote(num_cpus=1)
def raw_env_rate(seconds: float, max_episode_steps: int, seed: int) -> float:
    """Random-action steps per second of one environment, resets and scripted grasps included."""
    env = KukaGraspEnv(max_steps=max_episode_steps)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed, options={"task": KUKA_TASK_SPACE.hardest()})
    steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, size=3).astype(np.float32))
        steps += 1
        if terminated or truncated:
            env.reset()
    elapsed = time.perf_counter() - start
    env.close()
    return steps / elapsed


def training_rates(config: TrainConfig, run_dir: Path, teacher_url: str, warmup_iterations: int) -> tuple[float, float]:
    """Sampling-phase and whole-iteration rates of the training loop after warm-up: all measured
    steps over all the time they took, since iterations that hold episode ends (a reset and a
    scripted grasp of over a thousand physics steps) are far slower than those that do not."""
    name = curriculum_name(run_dir)
    with TeacherClient(teacher_url, name) as client:
        client.register(TEACHER, KUKA_TASK_SPACE, seed=config.seed)
    reports: list[IterationReport] = []
    Trainer(config, run_dir, teacher_url, name).run(reports.append)
    measured = reports[warmup_iterations:]
    sampling = len(measured) / sum(1.0 / r.metrics["perf/sample_steps_per_second"] for r in measured)
    whole = len(measured) / sum(1.0 / r.metrics["perf/steps_per_second"] for r in measured)
    return sampling, whole


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=2, help="rollout actors, W (default 2)")
    parser.add_argument("--envs-per-worker", type=int, default=TrainConfig.envs_per_worker)
    parser.add_argument("--rollout-length", type=int, default=PPOConfig.rollout_length)
    parser.add_argument(
        "--iterations",
        type=int,
        default=None,
        help="measured training iterations (default: enough for each environment to play "
        f"{MEASURED_STEPS_PER_ENV} steps, several episodes)",
    )
    parser.add_argument("--warmup-iterations", type=int, default=1, help="iterations left out (actor start-up)")
    parser.add_argument(
        "--raw-seconds",
        type=float,
        default=30.0,
        help="duration of the raw measurements, split before and after training (default 30)",
    )
    parser.add_argument("--max-episode-steps", type=int, default=TrainConfig.max_episode_steps)
    args = parser.parse_args()
    iterations = math.ceil(MEASURED_STEPS_PER_ENV / args.rollout_length) if args.iterations is None else args.iterations
    if iterations < 1:
        parser.error(f"--iterations must be at least 1, got {iterations}")

    config = TrainConfig(
        teacher=TEACHER,
        workers=args.workers,
        envs_per_worker=args.envs_per_worker,
        max_episode_steps=args.max_episode_steps,
        eval_every=0,
        checkpoint_every=10**9,
        ppo=PPOConfig(rollout_length=args.rollout_length),
    )
    config = replace(config, total_steps=config.batch_size * (iterations + args.warmup_iterations))

    ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING)
    try:
        with tempfile.TemporaryDirectory() as scratch, local_teacher_service(Path(scratch)) as teacher_url:
            half = args.raw_seconds / 2
            raw_before = ray.get(raw_env_rate.remote(half, args.max_episode_steps, seed=0))
            parallel_before = sum(
                ray.get([raw_env_rate.remote(half, args.max_episode_steps, seed=2 + w) for w in range(args.workers)])
            )
            run_dir = Path(scratch) / "collect-speed"
            sampling, whole = training_rates(config, run_dir, teacher_url, args.warmup_iterations)
            raw_after = ray.get(raw_env_rate.remote(half, args.max_episode_steps, seed=1))
            parallel_after = sum(
                ray.get(
                    [
                        raw_env_rate.remote(half, args.max_episode_steps, seed=2 + args.workers + w)
                        for w in range(args.workers)
                    ]
                )
            )
    finally:
        ray.shutdown()

    raw = (raw_before + raw_after) / 2
    parallel = (parallel_before + parallel_after) / 2
    ideal = args.workers * raw
    print(
        f"W={args.workers} workers x {args.envs_per_worker} envs, batch {config.batch_size} steps, "
        f"{iterations} measured iterations"
    )
    print(
        f"raw environment rate, 1 process, random actions: {raw:8.0f} steps/s "
        f"(before {raw_before:.0f}, after {raw_after:.0f})"
    )
    print(f"sampling phase, W workers, policy in the loop:  {sampling:8.0f} steps/s")
    print(f"ratio to W x raw ({ideal:.0f} steps/s):           {sampling / ideal:8.2f}")
    print(
        f"W raw processes at once, random actions:         {parallel:8.0f} steps/s "
        f"(before {parallel_before:.0f}, after {parallel_after:.0f})"
    )
    print(f"ratio to W raw processes at once:                {sampling / parallel:8.2f}")
    print(f"whole iteration (sampling + update + broadcast): {whole:8.0f} steps/s")


if __name__ == "__main__":
    main()
