"""The screen's test and its power calculation: exact, so a test can hold them to what the counting says."""

from __future__ import annotations

import pytest

from bench.screen_power import fisher_one_sided, fisher_power


def test_fishers_test_is_one_sided_on_the_good_runs() -> None:
    # 3 good of 3 against 0 of 3: the one table of the six runs' 20 that is as extreme, so p = 1/20.
    assert fisher_one_sided(3, 3, 0, 3) == pytest.approx(0.05)
    assert fisher_one_sided(0, 3, 3, 3) == pytest.approx(1.0)


def test_two_runs_an_arm_can_never_show_an_effect():
    assert fisher_power(1 / 3, 0.9, runs=2) == 0.0


def test_with_no_effect_the_test_rejects_no_more_often_than_its_level():
    assert fisher_power(0.5, 0.5, runs=10) <= 0.05


def test_power_grows_with_runs_and_with_a_larger_baseline_arm():
    powers = [fisher_power(1 / 3, 0.9, runs) for runs in (4, 6, 8, 10)]
    assert powers == sorted(powers) and powers[-1] == pytest.approx(0.77, abs=0.01)
    assert fisher_power(1 / 3, 0.9, 10, baseline_runs=11) > fisher_power(1 / 3, 0.9, 10)
