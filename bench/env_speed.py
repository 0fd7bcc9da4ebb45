"""How fast one core runs the KUKA grasp environment.

Random actions on the hardest task (the book's evaluation setting), counting resets and the
scripted grasps that end episodes, as a rollout worker would see it. Runs twice: resets that
restore the saved scene (the default) and resets that reload every model like the original.
Times are CPU seconds of this process, so other work on a shared machine inflates them less than
it would wall-clock times (which are printed too).

    .venv/bin/python bench/env_speed.py --steps 20000 --seed 0
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

from common.kuka.env import KukaGraspEnv


@dataclass
class SpeedReport:
    steps: int
    resets: int
    finished: int
    successes: int
    grasps: int
    total_s: float
    wall_s: float
    reset_s: float
    step_s: float
    grasp_s: float

    def lines(self, label: str) -> list[str]:
        plain_s = self.step_s - self.grasp_s
        return [
            f"{label}:",
            f"  env steps/s per core : {self.steps / self.total_s:8.0f}  (resets and grasps included;"
            f" {self.steps / self.wall_s:.0f} by the wall clock)",
            f"  mean reset           : {1e3 * self.reset_s / self.resets:8.2f} ms over {self.resets} resets",
            f"  mean step            : {1e6 * self.step_s / self.steps:8.1f} us over {self.steps} steps"
            " (grasps included)",
            f"  mean plain step      : {1e6 * plain_s / max(self.steps - self.grasps, 1):8.1f} us"
            " (steps that did not grasp)",
            f"  mean grasping step   : {1e3 * self.grasp_s / max(self.grasps, 1):8.2f} ms over {self.grasps} grasps",
            f"  successes            : {self.successes}/{self.finished} finished episodes",
        ]


def measure(steps: int, seed: int, reload_on_reset: bool) -> SpeedReport:
    env = KukaGraspEnv(reload_on_reset=reload_on_reset)
    actions = np.random.default_rng(seed).uniform(-1.0, 1.0, size=(steps, 3)).astype(np.float32)
    resets = finished = successes = grasps = 0
    reset_s = step_s = grasp_s = 0.0
    needs_reset = True
    start, wall_start = time.process_time(), time.perf_counter()
    for action in actions:
        if needs_reset:
            tick = time.process_time()
            env.reset(seed=seed + resets)
            reset_s += time.process_time() - tick
            resets += 1
        tick = time.process_time()
        _, _, terminated, truncated, info = env.step(action)
        elapsed = time.process_time() - tick
        step_s += elapsed
        if terminated:
            grasps += 1
            grasp_s += elapsed
        needs_reset = terminated or truncated
        finished += needs_reset
        successes += info["is_success"]
    total_s, wall_s = time.process_time() - start, time.perf_counter() - wall_start
    env.close()
    return SpeedReport(steps, resets, finished, successes, grasps, total_s, wall_s, reset_s, step_s, grasp_s)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000, help="env steps per measurement")
    parser.add_argument("--seed", type=int, default=0, help="seed of the actions and block placements")
    args = parser.parse_args()
    if args.steps < 1:
        parser.error("--steps must be at least 1")
    modes = (("saved-state resets", False), ("resets reloading every model, as the original", True))
    for label, reload_on_reset in modes:
        print("\n".join(measure(args.steps, args.seed, reload_on_reset).lines(label)))


if __name__ == "__main__":
    main()
