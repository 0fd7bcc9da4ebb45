"""Confidence intervals against published values and against their promised coverage."""

from __future__ import annotations

import math

import numpy as np
import pytest

from learner.evaluation.stats import mean_interval, wilson_interval


@pytest.mark.parametrize(
    ("successes", "trials", "low", "high"),
    [
        (81, 263, 0.2553, 0.3662),  # Newcombe (1998), Statistics in Medicine 17, table I
        (15, 148, 0.0624, 0.1605),  # ibid.
        (8, 10, 0.4902, 0.9433),
        (0, 10, 0.0, 0.2775),  # no successes: still a useful upper bound, unlike the normal interval
        (10, 10, 0.7225, 1.0),
    ],
)
def test_wilson_interval_matches_published_values(successes, trials, low, high):
    interval = wilson_interval(successes, trials)
    assert interval.estimate == pytest.approx(successes / trials)
    assert (interval.low, interval.high) == pytest.approx((low, high), abs=1e-4)
    assert 0.0 <= interval.low <= interval.estimate <= interval.high <= 1.0


def test_mean_interval_is_the_student_t_interval():
    interval = mean_interval([1.0, 2.0, 3.0, 4.0, 5.0])
    # mean 3, standard error sqrt(2.5 / 5), t(0.975, 4 degrees of freedom) = 2.7764
    assert interval.estimate == 3.0 and interval.samples == 5
    assert interval.half_width == pytest.approx(2.7764 * math.sqrt(0.5), abs=1e-4)
    assert (interval.low, interval.high) == pytest.approx((3.0 - interval.half_width, 3.0 + interval.half_width))


def test_mean_intervals_cover_the_true_mean_95_percent_of_the_time():
    rng = np.random.default_rng(0)
    covered = [
        interval.low <= 0.0 <= interval.high
        for interval in (mean_interval(rng.normal(0.0, 3.0, size=8)) for _ in range(4000))
    ]
    assert np.mean(covered) == pytest.approx(0.95, abs=0.01)


def test_a_single_value_has_no_interval_and_bad_input_is_refused():
    single = mean_interval([4.2])
    assert single.estimate == 4.2 and math.isnan(single.half_width)
    assert single.to_dict() == {"estimate": 4.2, "low": None, "high": None, "samples": 1}
    with pytest.raises(ValueError, match="no values"):
        mean_interval([])
    with pytest.raises(ValueError, match="finite"):
        mean_interval([1.0, float("nan")])
    with pytest.raises(ValueError, match="trials"):
        wilson_interval(0, 0)
    with pytest.raises(ValueError, match="successes"):
        wilson_interval(11, 10)
    with pytest.raises(ValueError, match="confidence"):
        wilson_interval(1, 10, confidence=95)
