"""What a bake-off concludes from its runs: each teacher's figures over seeds, with their intervals,
and how many steps each seed took to reach the success target. Pure computation over the runs'
evaluations and metrics logs; nothing here writes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from common.kuka import ENV_ID
from common.kuka.diagnostics import EpisodeDiagnostics
from learner.evaluation.checkpoint_evaluation import EvaluationResult
from learner.evaluation.stats import Interval, mean_interval, wilson_interval
from learner.experiments.bakeoff_runs import Run, curve_seeds, learning_curve
from learner.experiments.run_statistics import REPS, SEED, RunStatistics, run_statistics

SUCCESS_TARGET = 0.8
"""The success rate on the hardest task whose first crossing the report times."""
HALF_SUCCESS = 0.5
"""A lower bar the report also times, which a teacher may reach within the budget when 80% is not."""
STEP_TARGETS = (HALF_SUCCESS, SUCCESS_TARGET)
"""The success rates whose first crossing the report times."""
CURVE_WINDOW = 3
"""Consecutive in-run evaluations pooled for that reading, so it is not one small evaluation's luck."""
DEFAULT_BASELINE = "random"
"""The teacher every other is compared with, seed by seed: uniform random tasks, the curriculum a teacher
must beat to be worth its machinery (the field's usual baseline; the book reports none)."""


def steps_to_success(run: Run, target: float = SUCCESS_TARGET, window: int = CURVE_WINDOW) -> int | None:
    """The first step at which the last ``window`` in-run evaluations, pooled, reach ``target`` success
    (they share their episode count, so pooling is their mean); None if they never do.

    A moving mean rather than the first evaluation at the target: one evaluation of 20 episodes at a true 70%
    reaches 80% about one time in four, so the first crossing of a single one reads early, and a run that
    touches the target once and falls back is not counted as there. The step is that of the window's last
    evaluation, the first at which the run's curve says it is there. Since issue 59 the evaluations play
    stratified seeds (``learner.core.periodic_evaluation``), placed as the final evaluation's episodes are;
    an older run's (``curve_seeds``) played easier ones, and reads early."""
    curve = sorted(learning_curve(run, "eval/success_rate").items())
    for end in range(window, len(curve) + 1):
        if np.mean([rate for _, rate in curve[end - window : end]]) >= target:
            return curve[end - 1][0]
    return None


def seed_statistics(
    scores: Mapping[str, Sequence[float]], baseline: str = DEFAULT_BASELINE, reps: int = REPS, seed: int = SEED
) -> RunStatistics:
    """rliable's figures over each teacher's per-seed success rates (``run_statistics``), a seed counting as
    good at the success target; with the baseline not among the teachers, no probability of improvement."""
    return run_statistics(scores, baseline if baseline in scores else None, SUCCESS_TARGET, reps, seed)


def median_steps(steps: Sequence[int | None]) -> float | None:
    """The median over seeds, a seed that never got there counting as slower than all; None if the
    median seed never got there."""
    ordered = sorted(math.inf if value is None else value for value in steps)
    middle = len(ordered) // 2
    median = ordered[middle] if len(ordered) % 2 else (ordered[middle - 1] + ordered[middle]) / 2
    return None if math.isinf(median) else float(median)


@dataclass(frozen=True)
class TeacherResult:
    teacher: str
    runs: tuple[Run, ...]
    evaluations: tuple[EvaluationResult, ...]
    env: str = ENV_ID
    """The environment the runs trained and were evaluated on."""

    @property
    def returns(self) -> Interval:
        """Pooled over every seed's episodes; ``seed_returns`` shows the spread between seeds."""
        return mean_interval([episode.reward for result in self.evaluations for episode in result.episodes])

    @property
    def success_rate(self) -> Interval:
        episodes = [episode for result in self.evaluations for episode in result.episodes]
        return wilson_interval(sum(episode.success for episode in episodes), len(episodes))

    @property
    def diagnosed(self) -> list[tuple[EpisodeDiagnostics, bool]]:
        """Every seed's evaluation episodes with their diagnostics; empty if any evaluation predates them, as
        a table over some seeds only would pass for the teacher's."""
        if not all(result.diagnostics for result in self.evaluations):
            return []
        return [pair for result in self.evaluations for pair in result.diagnosed()]

    @property
    def seed_returns(self) -> list[float]:
        return [result.returns.estimate for result in self.evaluations]

    @property
    def seed_success_rates(self) -> list[float]:
        return [result.success_rate.estimate for result in self.evaluations]

    @property
    def success_over_seeds(self) -> Interval:
        """The mean of the seeds' success rates, with a Student-t interval over seeds (cut to [0, 1]):
        what a new seed may give."""
        interval = mean_interval(self.seed_success_rates)
        return replace(interval, low=max(interval.low, 0.0), high=min(interval.high, 1.0))

    @property
    def return_over_seeds(self) -> Interval:
        return mean_interval(self.seed_returns)

    @cached_property
    def _seed_steps(self) -> dict[float, list[int | None]]:
        """Per timed success rate, each seed's steps to it: read from the metrics logs once, as the
        report asks for them in both its files."""
        return {target: [steps_to_success(run, target) for run in self.runs] for target in STEP_TARGETS}

    @cached_property
    def seed_curve_seeds(self) -> list[str | None]:
        """Per seed, which seeds its in-run evaluations played (``bakeoff_runs.curve_seeds``)."""
        return [curve_seeds(run) for run in self.runs]

    @property
    def seed_steps_to_success(self) -> list[int | None]:
        return self.seed_steps_to(SUCCESS_TARGET)

    def seed_steps_to(self, target: float) -> list[int | None]:
        """Each seed's steps to ``target``, one of ``STEP_TARGETS``."""
        return self._seed_steps[target]
