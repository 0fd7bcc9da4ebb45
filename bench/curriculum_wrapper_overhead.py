"""What ``CurriculumWrapper`` costs a Stable-Baselines3 run on KukaGrasp-v0, measured in one run.

Two measurements, each alternating plain and wrapped rounds so that both see the same machine load:

1. SB3 PPO with 2 SubprocVecEnv workers learns ``--ppo-steps`` steps on the plain environment, then
   through the wrapper against a real teacher service started here; the median steps/s of each.
2. The time per episode, in one process with random actions: wall-clock, and the CPU time of the
   process (the wrapper's own work: taking a prefetched task, queueing the result, and its client's
   thread that sends the results), plain against wrapped. The difference between the two is time
   spent waiting: for the teacher's answer when a new batch of tasks is drawn, and for the CPU
   while the service, on the same cores, handles the requests.

Fair comparison: the wrapped environments play the ``fixed`` teacher's task, which is the hardest
one, the plain environment's default, so both simulate the same episodes. ``--max-episode-steps``
sets how often episodes end (the wrapper works once per episode): short ones are its worst case.

    .venv/bin/python bench/curriculum_wrapper_overhead.py --max-episode-steps 100
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import gymnasium
import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import SubprocVecEnv, VecMonitor

from common.client.curriculum_wrapper import CurriculumRegistration, CurriculumWrapper
from common.kuka import ENV_ID
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.process import ServiceProcess

CURRICULUM = "wrapper-overhead"
HARDEST = CurriculumRegistration("fixed", KUKA_TASK_SPACE)


def make_env(teacher_url: str | None, max_steps: int) -> Callable[[], gymnasium.Env]:
    def make() -> gymnasium.Env:
        env = gymnasium.make(ENV_ID, max_steps=max_steps)
        return env if teacher_url is None else CurriculumWrapper(env, teacher_url, CURRICULUM, register=HARDEST)

    return make


def ppo_steps_per_second(teacher_url: str | None, args: argparse.Namespace) -> tuple[float, int]:
    """Steps/s of ``model.learn`` (environment start-up excluded), and the episodes finished."""
    envs = VecMonitor(SubprocVecEnv([make_env(teacher_url, args.max_episode_steps) for _ in range(2)]))
    model = PPO("MlpPolicy", envs, n_steps=512, batch_size=256, seed=0, device="cpu")
    started = time.perf_counter()
    model.learn(total_timesteps=args.ppo_steps)
    elapsed = time.perf_counter() - started
    episodes = envs.episode_count
    envs.close()
    return model.num_timesteps / elapsed, episodes


def seconds_per_episode(teacher_url: str | None, args: argparse.Namespace) -> tuple[float, float]:
    """Mean wall time and process CPU time of one whole episode with random actions, in this process."""
    env = make_env(teacher_url, args.max_episode_steps)()
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, size=(args.max_episode_steps, 3)).astype(np.float32)
    env.reset(seed=0)
    started, cpu_started = time.perf_counter(), time.process_time()
    for _ in range(args.episodes):
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
        env.reset()
    elapsed, cpu = time.perf_counter() - started, time.process_time() - cpu_started
    env.close()
    return elapsed / args.episodes, cpu / args.episodes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-episode-steps", type=int, default=100)
    parser.add_argument("--ppo-steps", type=int, default=8192, help="PPO steps per round")
    parser.add_argument("--episodes", type=int, default=200, help="episodes per round of the per-episode measurement")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of each kind, alternating")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as folder, ServiceProcess(Path(folder) / "teacher.db") as teacher:
        print(f"max episode steps {args.max_episode_steps}; {args.rounds} alternating rounds of each\n")
        for label, measure, unit in (
            ("SB3 PPO, 2 SubprocVecEnv workers", lambda url: ppo_steps_per_second(url, args)[0], "steps/s"),
            ("one episode, wall-clock", lambda url: 1e3 * seconds_per_episode(url, args)[0], "ms"),
            ("one episode, CPU time of the process", lambda url: 1e3 * seconds_per_episode(url, args)[1], "ms"),
        ):
            plain, wrapped = [], []
            for _ in range(args.rounds):
                plain.append(measure(None))
                wrapped.append(measure(teacher.url))
            plain_median, wrapped_median = statistics.median(plain), statistics.median(wrapped)
            print(f"{label}:")
            print(f"  plain   : {plain_median:9.2f} {unit}  (rounds: {', '.join(f'{v:.2f}' for v in plain)})")
            print(f"  wrapped : {wrapped_median:9.2f} {unit}  (rounds: {', '.join(f'{v:.2f}' for v in wrapped)})")
            print(f"  wrapped / plain: {wrapped_median / plain_median:.3f}\n")


if __name__ == "__main__":
    main()
