"""How fast ALP-GMM samples, learns and refits in a 7-dimensional task space, on one core.

A refit (k = 2..10, full covariance, one EM init, 250 points) must stay under one second so a
service can refit every 250 episodes without falling behind.

Usage: .venv/bin/python bench/teacher_speed.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from collections.abc import Callable

from threadpoolctl import threadpool_limits

from common.client.task_space import Parameter, Task, TaskSpace
from teacher_service.teachers import EpisodeResult, FitJob, make_teacher
from teacher_service.teachers.alp_gmm import AlpGmmTeacher

DIMS = 7
FIT_RATE = 250
SAMPLES = 10_000


def progress_reward(task: Task, episode: int) -> float:
    """Reward that improves over time in one region and stays flat elsewhere, so ALP has structure."""
    distance = math.dist(task.values(), [0.25] * DIMS)
    return max(0.0, 1.0 - distance) * min(1.0, episode / 1000)


def fitted_teacher(seed: int) -> tuple[AlpGmmTeacher, FitJob]:
    """A teacher one result short of its second fit, and that fit's job."""
    space = TaskSpace(Parameter(f"x{i}", 0.0, 1.0) for i in range(DIMS))
    teacher = make_teacher("alp-gmm", space, seed, {"fit_rate": FIT_RATE})
    assert isinstance(teacher, AlpGmmTeacher)
    job = None
    for episode in range(2 * FIT_RATE):
        task = teacher.sample(1)[0]
        job = teacher.learn(EpisodeResult(task, progress_reward(task, episode)))
        if job is not None and episode < FIT_RATE:
            teacher.install(job.run())
    assert job is not None
    return teacher, job


def timed(action: Callable[[], object]) -> float:
    start = time.perf_counter()
    action()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="independent teachers to time")
    args = parser.parse_args()

    refits, samplings, updates = [], [], []
    with threadpool_limits(limits=1):
        for seed in range(args.repeats):
            teacher, job = fitted_teacher(seed)
            refits.append(timed(lambda: teacher.install(job.run())))  # noqa: B023  timed() runs it at once
            samplings.append(timed(lambda: teacher.sample(SAMPLES)))  # noqa: B023  timed() runs it at once
            tasks = teacher.sample(FIT_RATE - 1)
            updates.append(timed(lambda: [teacher.learn(EpisodeResult(t, 0.5)) for t in tasks]) / len(tasks))  # noqa: B023  timed() runs it at once

    print(f"ALP-GMM in {DIMS} dimensions, one BLAS thread, {args.repeats} teachers (median, max):")
    print(f"  refit on {FIT_RATE} points, k=2..10:  {statistics.median(refits):.3f} s, {max(refits):.3f} s")
    print(f"  sample {SAMPLES} tasks:            {statistics.median(samplings):.3f} s, {max(samplings):.3f} s")
    print(f"  update with one result:         {1e6 * statistics.median(updates):.0f} us, {1e6 * max(updates):.0f} us")


if __name__ == "__main__":
    main()
