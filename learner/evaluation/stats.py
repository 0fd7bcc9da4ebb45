"""Confidence intervals for evaluation results: pure functions, no I/O.

A mean over 100 noisy episodes, or a success rate, means little without its uncertainty: two
teachers whose intervals overlap have not been told apart. Returns get a Student-t interval
(exact for normal data, and right for the handful of seeds a bake-off has); success rates get the
Wilson score interval, which unlike the textbook normal one stays inside [0, 1] and behaves at 0%
and 100%.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

CONFIDENCE = 0.95


@dataclass(frozen=True)
class Interval:
    """An estimate with the bounds of its confidence interval (NaN bounds: too few samples to say)."""

    estimate: float
    low: float
    high: float
    samples: int

    @property
    def half_width(self) -> float:
        """The '±' of a symmetric interval."""
        return (self.high - self.low) / 2.0

    def to_dict(self) -> dict[str, float | int | None]:
        """JSON-ready; an unknown bound becomes null."""
        return {
            "estimate": self.estimate,
            "low": None if math.isnan(self.low) else self.low,
            "high": None if math.isnan(self.high) else self.high,
            "samples": self.samples,
        }


def _check_confidence(confidence: float) -> None:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")


def mean_interval(values: Sequence[float], confidence: float = CONFIDENCE) -> Interval:
    """The sample mean with its Student-t confidence interval; one value gives NaN bounds."""
    _check_confidence(confidence)
    data = np.asarray(values, dtype=np.float64).reshape(-1)
    if data.size == 0:
        raise ValueError("cannot take the mean of no values")
    if not np.isfinite(data).all():
        raise ValueError("values must be finite")
    mean = float(data.mean())
    if data.size == 1:
        return Interval(mean, math.nan, math.nan, 1)
    from scipy.stats import t  # here, not at the top: it takes a second to import and evaluation workers never need it

    standard_error = float(data.std(ddof=1)) / math.sqrt(data.size)
    half_width = float(t.ppf(0.5 + confidence / 2.0, df=data.size - 1)) * standard_error
    return Interval(mean, mean - half_width, mean + half_width, int(data.size))


def wilson_interval(successes: int, trials: int, confidence: float = CONFIDENCE) -> Interval:
    """The success rate with its Wilson score interval."""
    _check_confidence(confidence)
    if trials < 1:
        raise ValueError(f"trials must be at least 1, got {trials}")
    if not 0 <= successes <= trials:
        raise ValueError(f"successes must be between 0 and trials ({trials}), got {successes}")
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    rate = successes / trials
    denominator = 1.0 + z**2 / trials
    centre = (rate + z**2 / (2 * trials)) / denominator
    spread = z * math.sqrt(rate * (1 - rate) / trials + z**2 / (4 * trials**2)) / denominator
    # The bounds contain the estimate exactly, even where rounding would put 100% just outside.
    return Interval(rate, max(0.0, min(centre - spread, rate)), min(1.0, max(centre + spread, rate)), trials)
