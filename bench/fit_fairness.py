"""How long an ordinary ALP-GMM curriculum waits for its fits beside one with the costliest fits.

Real fits of real ALP-GMM teachers over the KUKA task space go through the service's FitRunner
(its pool of fit processes). The ordinary curriculum uses the defaults (fit_rate 250, 2..10
components, one EM init); the expensive one the costliest fit the parameter bounds allow
(fit_rate 2000, 1..16 components, 5 EM inits) and is kept busy: its next fit is due the moment
the last one lands. For the ordinary curriculum we measure each fit's latency, from falling due
to the teacher installing it, first alone and then (in a twin with the same seed, so the same
fits) beside the expensive one, once the pool's processes are up (a process starts when a fit
first needs it, which takes a second or more). The goal: beside it, each ordinary fit still lands
within twice its own fit time alone.

Usage: .venv/bin/python bench/fit_fairness.py [--ordinary-fits 8] [--processes 2]
"""

from __future__ import annotations

import argparse
import asyncio
import math
import statistics
import time

from threadpoolctl import threadpool_limits

from common.client.task_space import Task
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.fits import FitOutcome, FitRunner
from teacher_service.metrics import ServiceMetrics
from teacher_service.teachers import EpisodeResult, FitJob, make_teacher
from teacher_service.teachers.alp_gmm import AlpGmmTeacher

ORDINARY = {"fit_rate": 250, "min_components": 2, "max_components": 10, "nb_em_init": 1}
EXPENSIVE = {"fit_rate": 2000, "min_components": 1, "max_components": 16, "nb_em_init": 5}
GAP_S = 0.5
"""Pause between two ordinary fits, so each falls due on its own."""


def reward(task: Task, episode: int) -> float:
    """Improves over time near the easy corner and stays flat elsewhere, so ALP has structure."""
    unit = KUKA_TASK_SPACE.to_unit(KUKA_TASK_SPACE.to_array(task))
    return max(0.0, 1.0 - math.dist(unit, [0.2] * len(unit))) * min(1.0, episode / 2000)


class Curriculum:
    """A teacher fed made-up results, and how long each of its fits took to land."""

    def __init__(self, name: str, params: dict[str, int], seed: int) -> None:
        self.name = name
        teacher = make_teacher("alp-gmm", KUKA_TASK_SPACE, seed, params)
        assert isinstance(teacher, AlpGmmTeacher)
        self.teacher = teacher
        self.landed: asyncio.Event = asyncio.Event()
        self.latencies: list[float] = []
        self.fit_seconds: list[float] = []
        self.pending = False
        self._due_at = 0.0

    def next_fit(self) -> FitJob:
        """Feed results until a fit falls due."""
        while True:
            task = self.teacher.sample(1)[0]
            job = self.teacher.learn(EpisodeResult(task, reward(task, self.teacher.results_seen)))
            if job is not None:
                return job

    def submit(self, runner: FitRunner) -> None:
        job = self.next_fit()
        self.landed.clear()
        self.pending = True
        self._due_at = time.perf_counter()
        runner.submit(self.name, job, self._installed)

    def _installed(self, outcome: FitOutcome) -> None:
        if outcome.error is not None:
            raise RuntimeError(f"{self.name}: fit {outcome.index} failed: {outcome.error}")
        self.teacher.install(outcome.output)
        self.pending = False
        self.latencies.append(time.perf_counter() - self._due_at)
        self.fit_seconds.append(outcome.finished_at - outcome.started_at)
        self.landed.set()


async def fit_in_turn(
    runner: FitRunner, curriculum: Curriculum, fits: int, gap_s: float, beside: CostlyLoad | None = None
) -> int:
    """Run ``fits`` fits one after another; return how many landed while ``beside`` had a fit pending."""
    overlapped = 0
    for _ in range(fits):
        curriculum.submit(runner)
        await curriculum.landed.wait()
        overlapped += beside is not None and beside.pending
        await asyncio.sleep(gap_s)
    return overlapped


class CostlyLoad:
    """The curriculum with the costliest fits, kept busy: the moment one fit lands the next falls
    due. Its results are fed once, up front, and the same fit is submitted again and again, so
    making up its results takes no CPU from the fits being timed."""

    def __init__(self, name: str, seed: int) -> None:
        self.name = name
        self.job = Curriculum(name, EXPENSIVE, seed).next_fit()
        self.fit_seconds: list[float] = []
        self.pending = False
        self._landed = asyncio.Event()

    async def keep_busy(self, runner: FitRunner, until: asyncio.Event) -> None:
        index = self.job.index
        while not until.is_set():
            self._landed.clear()
            self.pending = True
            runner.submit(self.name, FitJob(index, self.job.run), self._done)
            await self._landed.wait()
            index += 1

    def _done(self, outcome: FitOutcome) -> None:
        if outcome.error is not None:
            raise RuntimeError(f"{self.name}: fit {outcome.index} failed: {outcome.error}")
        self.pending = False
        self.fit_seconds.append(outcome.finished_at - outcome.started_at)
        self._landed.set()


async def measure(ordinary_fits: int, processes: int) -> None:
    runner = FitRunner(processes, 600.0, ServiceMetrics())
    runner.start(asyncio.get_running_loop())
    try:
        # Twins: the same seed and results, so the twin beside the expensive curriculum runs the
        # very fits the first ran alone, and each fit's latency compares with its own time alone.
        alone = Curriculum("ordinary-alone", ORDINARY, seed=1)
        beside = Curriculum("ordinary-beside", ORDINARY, seed=1)
        started = time.perf_counter()
        await asyncio.gather(*(fit_in_turn(runner, c, 1, 0.0) for c in (alone, beside)))
        print(f"first fits, starting {processes} fit processes: {time.perf_counter() - started:.2f} s (not counted)")
        alone.latencies.clear()
        alone.fit_seconds.clear()
        await fit_in_turn(runner, alone, ordinary_fits, GAP_S)

        expensive = CostlyLoad("expensive", seed=2)
        done = asyncio.Event()
        busy = asyncio.create_task(expensive.keep_busy(runner, done))
        await asyncio.sleep(GAP_S)  # its first fit is running
        beside.latencies.clear()
        overlapped = await fit_in_turn(runner, beside, ordinary_fits, GAP_S, beside=expensive)
        done.set()
        await busy
    finally:
        runner.close()

    own = statistics.median(alone.fit_seconds)
    ratios = [late / fit for late, fit in zip(beside.latencies, alone.fit_seconds, strict=True)]
    print(f"fit processes: {processes}; ordinary fits per phase: {ordinary_fits}")
    print(f"ordinary fit time alone (in its process):  median {own:.3f} s, max {max(alone.fit_seconds):.3f} s")
    print(f"ordinary latency alone (due -> installed): median {statistics.median(alone.latencies):.3f} s")
    print(
        f"ordinary latency beside the expensive one: median {statistics.median(beside.latencies):.3f} s, "
        f"max {max(beside.latencies):.3f} s = {max(beside.latencies) / own:.1f}x the median fit time alone; "
        f"{overlapped} of {ordinary_fits} landed while an expensive fit was pending"
    )
    print(
        "each fit's latency beside over the same fit's time alone (goal <= 2x): "
        f"median {statistics.median(ratios):.2f}x, max {max(ratios):.2f}x, over 2x: {sum(r > 2 for r in ratios)}"
    )
    print(
        f"expensive fits in the pool, beside it: {len(expensive.fit_seconds)}, "
        f"each {', '.join(f'{s:.2f}' for s in expensive.fit_seconds)} s"
    )


def costliest_fit_alone() -> float:
    """One fit at the costliest parameters, in this process with one BLAS thread, as a fit process runs it."""
    job = CostlyLoad("costliest", seed=3).job
    with threadpool_limits(limits=1):
        started = time.perf_counter()
        job.run()
        return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ordinary-fits", type=int, default=8, help="ordinary fits timed alone and beside")
    parser.add_argument("--processes", type=int, default=2, help="fit processes (KC_FIT_PROCESSES)")
    args = parser.parse_args()
    asyncio.run(measure(args.ordinary_fits, args.processes))
    print(f"costliest allowed fit alone ({EXPENSIVE}): {costliest_fit_alone():.2f} s")


if __name__ == "__main__":
    main()
