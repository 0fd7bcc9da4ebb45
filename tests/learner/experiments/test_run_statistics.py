"""Run statistics over a few runs per arm (``learner.experiments.run_statistics``), against figures worked
out by hand."""

from __future__ import annotations

import json
import math

import imageio.v3 as iio
import numpy as np
import pytest
from rliable import library, metrics

from learner.experiments.run_statistics import (
    _improvement,
    _share_above,
    plot_performance_profile,
    run_statistics,
    statistics_table,
)

REPS = 200
"""Enough resamples for the checks here, few enough to keep them quick."""


def test_the_iqm_is_the_mean_of_the_middle_half_and_the_mean_the_plain_mean():
    # Eight runs: the IQM drops the two lowest and the two highest.
    scores = [0.0, 0.9, 0.1, 1.0, 0.2, 0.0, 0.3, 0.4]
    arm = run_statistics({"arm": scores}, reps=REPS).arms["arm"]
    assert arm.iqm.estimate == pytest.approx((0.1 + 0.2 + 0.3 + 0.4) / 4)
    assert arm.mean.estimate == pytest.approx(sum(scores) / 8)
    for interval in (arm.iqm, arm.mean):
        assert 0.0 <= interval.low < interval.estimate < interval.high <= 1.0 and interval.samples == 8
    # Five runs: one dropped at each end; under four nothing is, and the IQM is the mean.
    five = run_statistics({"arm": [0.718, 0.23, 0.422, 0.89, 0.848]}, reps=REPS).arms["arm"]
    assert five.iqm.estimate == pytest.approx((0.422 + 0.718 + 0.848) / 3)
    three = run_statistics({"arm": [0.1, 0.5, 0.9]}, reps=REPS).arms["arm"]
    assert three.iqm.estimate == pytest.approx(0.5) == three.mean.estimate


def test_the_probability_of_improvement_counts_every_pair_of_runs_and_ties_half():
    scores = {
        "base": [0.5, 0.0],
        "dominating": [0.9, 0.6, 0.7],
        "dominated": [0.0, 0.0],
        "mixed": [1.0, 0.5],
        "same": [0.5, 0.0],
    }
    arms = run_statistics(scores, baseline="base", reps=REPS).arms
    assert arms["base"].improvement is None
    dominating = arms["dominating"].improvement
    assert (dominating.estimate, dominating.low, dominating.high) == (1.0, 1.0, 1.0)
    # Against 0.5 and 0.0: 0.0 ties with 0.0 (a half) and loses to 0.5, twice: 1 of 4 pairs.
    assert arms["dominated"].improvement.estimate == pytest.approx(0.25)
    # 1.0 beats both; 0.5 ties with 0.5 and beats 0.0: 3.5 of 4.
    assert arms["mixed"].improvement.estimate == pytest.approx(0.875)
    assert arms["same"].improvement.estimate == pytest.approx(0.5)
    assert arms["mixed"].improvement.low < 0.875 <= arms["mixed"].improvement.high == 1.0


def test_the_improvement_resampled_is_rliables_probability_of_improvement():
    generator = np.random.default_rng(0)
    for runs_x, runs_y in [(1, 1), (2, 5), (5, 3), (10, 10)]:
        for _ in range(20):
            # Scores on a coarse grid, so that ties between runs are common.
            x, y = (generator.integers(0, 5, (runs, 1)) / 4 for runs in (runs_x, runs_y))
            assert _improvement(x, y) == pytest.approx(metrics.probability_of_improvement(x, y))


def test_the_share_of_runs_at_or_above_the_threshold_carries_its_wilson_interval():
    # 9 of 10 runs at 80% or more, one exactly at it.
    scores = [0.8, 0.85, 0.9, 0.95, 1.0, 0.81, 0.99, 0.88, 0.83, 0.2]
    reaching = run_statistics({"arm": scores}, reps=REPS).arms["arm"].reaching
    assert reaching.estimate == pytest.approx(0.9) and reaching.samples == 10
    assert (reaching.low, reaching.high) == pytest.approx((0.5958, 0.9821), abs=1e-4)
    assert run_statistics({"arm": scores}, threshold=0.81, reps=REPS).arms["arm"].reaching.estimate == 0.8


def test_the_figures_are_deterministic_given_the_seed_and_leave_numpys_generator_alone():
    scores = {"a": [0.1, 0.4, 0.35, 0.9], "b": [0.2, 0.25, 0.3]}
    np.random.seed(123)
    expected_draw = np.random.random()
    np.random.seed(123)
    first = run_statistics(scores, baseline="b", reps=REPS, seed=7)
    assert np.random.random() == expected_draw, "the caller's generator state is put back"
    assert run_statistics(scores, baseline="b", reps=REPS, seed=7) == first
    other = run_statistics(scores, baseline="b", reps=REPS, seed=8)
    assert other.arms["a"].mean.estimate == first.arms["a"].mean.estimate
    assert other.arms["a"].mean != first.arms["a"].mean, "another seed resamples otherwise"
    # An arm's figures do not depend on the arms beside it.
    alone = run_statistics({"a": scores["a"]}, reps=REPS, seed=7)
    assert alone.arms["a"].iqm == first.arms["a"].iqm and alone.arms["a"].mean == first.arms["a"].mean


def test_arms_of_one_to_three_runs_give_figures_and_say_what_they_cannot():
    scores = {"one": [0.7], "two": [0.2, 0.6], "three": [0.0, 0.0, 0.0]}
    arms = run_statistics(scores, baseline="two", reps=REPS).arms
    one = arms["one"]
    # One run: nothing to resample, so no bootstrap bounds, for its own figures and its improvement.
    assert one.iqm.estimate == one.mean.estimate == 0.7 and math.isnan(one.iqm.low) and math.isnan(one.mean.high)
    assert one.improvement.estimate == 1.0 and math.isnan(one.improvement.low) and math.isnan(one.improvement.high)
    assert one.reaching.estimate == 0.0 and 0.0 < one.reaching.high < 1.0
    two = arms["two"]
    assert (two.mean.low, two.mean.high) == (0.2, 0.6), "two runs resample to their own extremes at most"
    three = arms["three"]
    assert (three.iqm.estimate, three.iqm.low, three.iqm.high) == (0.0, 0.0, 0.0)
    assert three.improvement.estimate == 0.0, "below both of the baseline's runs, every time"
    record = json.loads(json.dumps(run_statistics(scores, baseline="two", reps=REPS).to_dict()))
    assert record["arms"]["one"]["iqm"] == {"estimate": 0.7, "low": None, "high": None, "samples": 1}
    assert record["arms"]["two"]["improvement_over_baseline"] is None and record["baseline"] == "two"
    assert record["arms"]["three"]["scores"] == [0.0, 0.0, 0.0] and record["threshold"] == 0.8


def test_bad_arms_are_refused():
    with pytest.raises(ValueError, match="baseline 'random' is not among the arms"):
        run_statistics({"currot": [0.5]}, baseline="random")
    with pytest.raises(ValueError, match="at least one run"):
        run_statistics({"currot": []})
    with pytest.raises(ValueError, match=r"fractions in \[0, 1\]"):
        run_statistics({"currot": [0.5, 1.5]})
    with pytest.raises(ValueError, match="reps"):
        run_statistics({"currot": [0.5, 0.6]}, reps=0)


def test_the_table_names_each_arm_and_the_baseline():
    statistics = run_statistics({"random": [0.2, 0.1], "currot": [0.9, 0.85]}, baseline="random", reps=REPS)
    table = statistics_table(statistics, {"random": "Uniform random tasks", "currot": "CURROT"})
    assert table[0].endswith("| Runs at 80% or more [Wilson] | P(improvement over Uniform random tasks) [CI] |")
    assert table[2].startswith("| Uniform random tasks | 2 | 15% [10%, 20%] | 15% [10%, 20%] | 0% [0%, ")
    assert table[2].endswith("| — |")
    assert table[3].endswith("| 100% [34%, 100%] | 1.00 [1.00, 1.00] |")
    single = statistics_table(run_statistics({"fixed": [0.0]}, reps=REPS))
    assert single[0].endswith("P(improvement over no baseline) [CI] |")
    assert single[2] == "| fixed | 1 | 0% [n/a] | 0% [n/a] | 0% [0%, 79%] | — |"


def test_the_profile_is_rliables_score_distribution_and_is_drawn(tmp_path):
    scores = np.array([[0.1], [0.5], [0.5], [0.9]])
    taus = np.linspace(0.0, 1.0, 101)
    assert np.array_equal(_share_above(scores, taus), library.score_distributions(scores, taus))
    assert _share_above(scores, np.array([0.0, 0.5, 0.95])).tolist() == [1.0, 0.25, 0.0]
    path = tmp_path / "profile.png"
    plot_performance_profile(path, {"currot": [0.7, 0.2, 0.9], "fixed": [0.0]}, {"currot": "CURROT"}, reps=REPS)
    image = iio.imread(path)
    assert image.ndim == 3 and image.shape[0] > 300 and image.shape[1] > 500
