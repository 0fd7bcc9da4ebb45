"""Statistics over a handful of runs per arm, computed with rliable (Agarwal et al., "Deep RL at the Edge
of the Statistical Precipice", NeurIPS 2021): what a bake-off, a screen or a level side-by-side can tell
apart with its seeds. Pure computation, and one plot.

Each arm's runs give one score each, a fraction in [0, 1] such as a final policy's hardest-task success.
Point estimates over a few seeds mis-rank arms (the paper's finding), so every figure comes with its
interval: the interquartile mean (IQM: the mean of the middle half of the runs, robust to one freak seed)
and the mean, each with a stratified-bootstrap percentile interval; the share of runs at or above a
threshold, with its Wilson interval; the probability of improvement of each arm over a named baseline,
P(X > Y) over every pair of their runs with ties counted half, with an interval from rliable's bootstrap
of each arm's runs on their own (its figure computed here, equal to rliable's but without the scipy test
rliable runs for it). A performance profile draws the share of each arm's runs above every score, with
bootstrap bands.

Degenerate cases are reported, not refused: an arm of one run has nothing to resample, so its bootstrap
bounds, and those of an improvement it takes part in, are NaN (``Interval``'s "too few to say"); under
four runs the IQM trims nothing and equals the mean; and a bootstrap over two or three runs draws from so
few distinct resamples that its interval is narrower than the truth.

Deterministic given ``seed``: rliable's bootstraps draw from numpy's global generator, so each figure
seeds it for its own computation (an arm's figures do not depend on which other arms came along) and
puts the generator's state back after.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from learner.commands.arguments import int_between
from learner.core.figure_file import save_png
from learner.evaluation.stats import CONFIDENCE, Interval, wilson_interval

THRESHOLD = 0.8
"""The score a run must reach to count as a good one (a success rate of 80% on the hardest task)."""
REPS = 10_000
"""Bootstrap resamples per interval. Over a few runs the bootstrap's distribution is a handful of values, and
with fewer resamples a bound moves between neighbouring ones from one seed to the next; rliable's default for
intervals, more again, would take minutes per bake-off (``docs/results/bakeoff-hard.md`` measures both)."""
MIN_REPS, MAX_REPS = 100, 100_000
"""The resamples a command may ask for: fewer make bounds that jump, more cost minutes per report."""
REPS_HELP = f"bootstrap resamples per interval (default {REPS:_}; {MIN_REPS} to {MAX_REPS:_})"
bootstrap_reps = int_between(MIN_REPS, MAX_REPS)
"""The command-line type of a number of resamples: a whole number from ``MIN_REPS`` to ``MAX_REPS``."""
SEED = 0
PROFILE_POINTS = 101
"""Scores at which the performance profile is evaluated, evenly over [0, 1]."""

Matrix = NDArray[np.float64]
"""One arm's scores as rliable takes them: runs x tasks, here one task."""


@dataclass(frozen=True)
class ArmStatistics:
    """One arm's figures over its runs."""

    scores: tuple[float, ...]
    iqm: Interval
    mean: Interval
    reaching: Interval
    """The share of runs scoring at or above the threshold, with its Wilson interval."""
    improvement: Interval | None
    """P(a run of this arm scores above a run of the baseline), ties counting half; None for the baseline
    itself, or when there is none."""

    @property
    def runs(self) -> int:
        return len(self.scores)

    def to_dict(self) -> dict[str, Any]:
        return {
            "runs": self.runs,
            "scores": list(self.scores),
            "iqm": self.iqm.to_dict(),
            "mean": self.mean.to_dict(),
            "share_at_or_above_threshold": self.reaching.to_dict(),
            "improvement_over_baseline": None if self.improvement is None else self.improvement.to_dict(),
        }


@dataclass(frozen=True)
class RunStatistics:
    """Every arm's figures, and what they were computed with."""

    arms: Mapping[str, ArmStatistics]
    baseline: str | None
    threshold: float
    confidence: float
    reps: int
    seed: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, saying how each figure was computed, so a results file can be read without this module."""
        return {
            "method": "rliable: IQM and mean with stratified-bootstrap percentile intervals; the share of runs at "
            "or above the threshold with a Wilson interval; P(arm > baseline) over pairs of runs, ties counted "
            "half, with an independent stratified-bootstrap interval; NaN (null) bounds for a single run",
            "baseline": self.baseline,
            "threshold": self.threshold,
            "confidence": self.confidence,
            "reps": self.reps,
            "seed": self.seed,
            "arms": {arm: statistics.to_dict() for arm, statistics in self.arms.items()},
        }


@contextlib.contextmanager
def _seeded(seed: int) -> Iterator[None]:
    """rliable resamples with numpy's global generator: seed it for one computation, then restore it."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


def _matrix(scores: Sequence[float]) -> Matrix:
    values = np.asarray(scores, dtype=np.float64).reshape(-1, 1)
    if values.size == 0:
        raise ValueError("an arm needs at least one run")
    if not (np.isfinite(values).all() and (values >= 0.0).all() and (values <= 1.0).all()):
        raise ValueError(f"scores must be fractions in [0, 1], got {list(scores)}")
    return values


def _bootstrap(statistic: Callable[..., Any], data: list[Matrix], reps: int, seed: int, confidence: float) -> Interval:
    """``statistic`` of the arrays in ``data`` with its stratified-bootstrap percentile interval, each array
    resampled on its own; NaN bounds when an array holds a single run."""
    from rliable import library  # type: ignore[import-untyped]  # here: it takes seconds to import

    estimate = float(statistic(*data))
    runs = len(data[0])
    if min(len(array) for array in data) < 2:
        return Interval(estimate, math.nan, math.nan, runs)
    with _seeded(seed):
        _, intervals = library.get_interval_estimates(
            {"arm": data[0] if len(data) == 1 else data},
            lambda *arrays: np.atleast_1d(statistic(*arrays)),
            reps=reps,
            confidence_interval_size=confidence,
        )
    low, high = (float(bound) for bound in np.asarray(intervals["arm"]).reshape(2))
    return Interval(estimate, low, high, runs)


def _improvement(x: Matrix, y: Matrix) -> float:
    """P(a run of x scores above a run of y), ties counting half, over every pair: rliable's
    ``probability_of_improvement`` for one task, without the Mann-Whitney p-value it computes through scipy
    and discards, which costs milliseconds in each of the bootstrap's resamples."""
    return float(((x > y.T) + 0.5 * (x == y.T)).mean())


def run_statistics(
    scores: Mapping[str, Sequence[float]],
    baseline: str | None = None,
    threshold: float = THRESHOLD,
    reps: int = REPS,
    seed: int = SEED,
    confidence: float = CONFIDENCE,
) -> RunStatistics:
    """Each arm's IQM, mean, share of runs at or above ``threshold`` and, given a ``baseline`` among the
    arms, probability of improvement over it, all with their intervals."""
    from rliable import metrics

    if baseline is not None and baseline not in scores:
        raise ValueError(f"baseline {baseline!r} is not among the arms ({', '.join(scores)})")
    if reps < 1:
        raise ValueError(f"reps must be at least 1, got {reps}")
    matrices = {arm: _matrix(values) for arm, values in scores.items()}
    arms = {}
    for arm, matrix in matrices.items():
        improvement = None
        if baseline is not None and arm != baseline:
            pair = [matrix, matrices[baseline]]
            improvement = _bootstrap(_improvement, pair, reps, seed, confidence)
        arms[arm] = ArmStatistics(
            scores=tuple(float(value) for value in matrix[:, 0]),
            iqm=_bootstrap(metrics.aggregate_iqm, [matrix], reps, seed, confidence),
            mean=_bootstrap(metrics.aggregate_mean, [matrix], reps, seed, confidence),
            reaching=wilson_interval(int((matrix >= threshold).sum()), len(matrix), confidence),
            improvement=improvement,
        )
    return RunStatistics(arms, baseline, threshold, confidence, reps, seed)


def _share_above(scores: Matrix, taus: NDArray[np.float64]) -> NDArray[np.float64]:
    """rliable's score distribution (the share of runs above each tau) for all taus at once: its own takes
    one Python call per tau and resample."""
    return np.asarray((scores.reshape(-1, 1) > taus).mean(axis=0), dtype=np.float64)


def plot_performance_profile(
    path: Path,
    scores: Mapping[str, Sequence[float]],
    labels: Mapping[str, str] | None = None,
    title: str = "",
    reps: int = REPS,
    seed: int = SEED,
    confidence: float = CONFIDENCE,
) -> None:
    """The share of each arm's runs scoring above every score, with bootstrap bands, as a PNG at ``path``
    (``labels`` names the arms in the legend): where arms cross, and how far apart their runs spread, which
    a table of summaries hides."""
    from matplotlib.figure import Figure
    from rliable import library, plot_utils

    taus = np.linspace(0.0, 1.0, PROFILE_POINTS)
    profiles, bands = {}, {}
    for arm, values in scores.items():
        name = (labels or {}).get(arm, arm)
        with _seeded(seed):
            profile, band = library.create_performance_profile(
                {name: _matrix(values)},
                taus,
                custom_profile_func=_share_above,
                reps=reps,
                confidence_interval_size=confidence,
            )
        profiles[name] = profile[name]
        bands[name] = band[name]
    figure = Figure(figsize=(10.0, 4.8), layout="constrained")
    axes = figure.add_subplot()
    plot_utils.plot_performance_profiles(
        profiles,
        taus,
        performance_profile_cis=bands,
        ax=axes,
        xlabel=r"score $\tau$",
        ylabel=r"share of runs with score $> \tau$",
        labelsize="medium",
        ticklabelsize="medium",
    )
    axes.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize="small")
    axes.set_title(title or f"Performance profiles ({confidence:.0%} bootstrap bands over runs)", fontsize="medium")
    save_png(figure, path, dpi=110)


def _percent(interval: Interval) -> str:
    if math.isnan(interval.low):
        return f"{interval.estimate:.0%} [n/a]"
    return f"{interval.estimate:.0%} [{interval.low:.0%}, {interval.high:.0%}]"


def _probability(interval: Interval | None) -> str:
    if interval is None:
        return "—"
    if math.isnan(interval.low):
        return f"{interval.estimate:.2f} [n/a]"
    return f"{interval.estimate:.2f} [{interval.low:.2f}, {interval.high:.2f}]"


def statistics_table(statistics: RunStatistics, labels: Mapping[str, str] | None = None) -> list[str]:
    """The figures as Markdown table lines, one row per arm (``labels`` names them)."""
    baseline = statistics.baseline
    against = "no baseline" if baseline is None else (labels or {}).get(baseline, baseline)
    lines = [
        f"| Arm | Runs | IQM [{statistics.confidence:.0%} CI] | Mean [{statistics.confidence:.0%} CI] "
        f"| Runs at {statistics.threshold:.0%} or more [Wilson] | P(improvement over {against}) [CI] |",
        "|---|---|---|---|---|---|",
    ]
    for arm, figures in statistics.arms.items():
        lines.append(
            f"| {(labels or {}).get(arm, arm)} | {figures.runs} | {_percent(figures.iqm)} | {_percent(figures.mean)} "
            f"| {_percent(figures.reaching)} | {_probability(figures.improvement)} |"
        )
    return lines
