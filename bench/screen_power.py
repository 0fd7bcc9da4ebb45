"""The power of a screen whose outcome is bimodal: the share of runs that reach a bar (80% hardest-point
success) in a baseline arm and a lever's arm, compared by Fisher's exact test, one-sided.

Exact, not simulated: every pair of outcomes (good runs in each arm) is weighed by its binomial probability,
and the power is the total weight of the pairs the test rejects at ``--alpha``. Used to fix a screen's seed
count before it runs (docs/results/bakeoff-hard.md, "Issue 80's screens").

    .venv/bin/python bench/screen_power.py --baseline 0.33 --lever 0.9 --runs 2 4 6 8 10 12
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.stats import binom, fisher_exact


def fisher_one_sided(good: int, runs: int, baseline_good: int, baseline_runs: int) -> float:
    """P-value of Fisher's exact test that an arm's share of good runs is above the baseline's."""
    table = [[good, runs - good], [baseline_good, baseline_runs - baseline_good]]
    return float(fisher_exact(table, alternative="greater").pvalue)


def fisher_power(
    baseline: float, lever: float, runs: int, alpha: float = 0.05, baseline_runs: int | None = None
) -> float:
    """Chance that a one-sided Fisher test at ``alpha`` finds the lever's share of good runs above the
    baseline's, with ``runs`` lever runs and ``baseline_runs`` baseline runs (as many by default), when the true
    shares are ``baseline`` and ``lever``."""
    others = runs if baseline_runs is None else baseline_runs
    weights = np.outer(binom.pmf(np.arange(others + 1), others, baseline), binom.pmf(np.arange(runs + 1), runs, lever))
    power = 0.0
    for good_baseline in range(others + 1):
        for good_lever in range(runs + 1):
            if fisher_one_sided(good_lever, runs, good_baseline, others) <= alpha:
                power += weights[good_baseline, good_lever]
    return float(power)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", type=float, required=True, help="the baseline arm's true share of good runs")
    parser.add_argument("--lever", type=float, required=True, help="the lever arm's true share of good runs")
    parser.add_argument("--runs", type=int, nargs="+", default=[2, 4, 6, 8, 10], help="runs per arm to try")
    parser.add_argument("--alpha", type=float, default=0.05, help="the one-sided test's level (default 0.05)")
    parser.add_argument("--baseline-runs", type=int, help="the baseline arm's runs, where it has its own count")
    args = parser.parse_args()
    print(f"good-run share {args.baseline:g} -> {args.lever:g}, one-sided Fisher at {args.alpha:g}")
    for runs in args.runs:
        power = fisher_power(args.baseline, args.lever, runs, args.alpha, args.baseline_runs)
        others = runs if args.baseline_runs is None else args.baseline_runs
        print(f"  {runs:3d} lever runs, {others} baseline runs: power {power:.2f}")


if __name__ == "__main__":
    main()
