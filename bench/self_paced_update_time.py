"""How long one SPDL update takes, which decides whether it runs inline or as a FitJob.

For each (parameters, results per update), the update is timed on the results of a student that
succeeds on the easier part of the tasks drawn, both when the Gaussian is above the bar (moved
toward the target under both constraints) and below it (climbing performance). Prints the median
and the largest CPU time per update, so that a machine shared with other work distorts it less.

    .venv/bin/python bench/self_paced_update_time.py --repeats 20
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from teacher_service.teachers.self_paced import Gaussian, update_gaussian

SIZES = ((2, 100), (6, 100), (6, 250), (10, 250), (32, 1000), (64, 1000))
"""(task parameters, results per update): the KUKA space, a large space, and the largest allowed."""


def time_updates(dims: int, results: int, bar: float, repeats: int, seed: int) -> list[float]:
    rng = np.random.default_rng(seed)
    old = Gaussian(np.full(dims, 0.2), np.full(dims, np.log(0.05)))
    target = Gaussian(np.ones(dims), np.full(dims, np.log(0.05)))
    times = []
    for _ in range(repeats):
        points = np.clip(old.mean + 0.05 * rng.standard_normal((results, dims)), 0.0, 1.0)
        scores = (points.max(axis=1) <= 0.25).astype(float)
        started = time.process_time()
        update_gaussian(old, target, points, scores, bar, 0.1)
        times.append(time.process_time() - started)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    print("params  results  branch        median ms   max ms")
    for dims, results in SIZES:
        for branch, bar in (("toward target", 0.0), ("below bar", 1.0)):
            times = time_updates(dims, results, bar, args.repeats, seed=dims * results)
            print(
                f"{dims:6d}  {results:7d}  {branch:13s} {1e3 * statistics.median(times):9.1f} {1e3 * max(times):8.1f}"
            )


if __name__ == "__main__":
    main()
