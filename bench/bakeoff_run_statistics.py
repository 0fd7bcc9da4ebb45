"""A bake-off's run statistics recomputed from its ``results.json`` alone: for a bake-off reported before
them (``benchmarks/bakeoff-hard/bakeoff-issue59``), or against another baseline teacher.

Writes ``run_statistics.md``, ``run_statistics.json`` and ``performance_profile.png`` to ``--out`` (default:
beside the results file, which stays as it is; a bake-off's own report, ``kuka-curriculum bakeoff``, writes
the same figures into its results files). Seconds to a minute, most of it the bootstrap of the probability
of improvement.

    .venv/bin/python bench/bakeoff_run_statistics.py benchmarks/bakeoff-hard/bakeoff-issue59/results.json
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from learner.core.config import TEACHERS  # noqa: E402
from learner.experiments.bakeoff_report import (  # noqa: E402
    RUN_STATISTICS_MARKDOWN,
    recompute_run_statistics,
)
from learner.experiments.bakeoff_statistics import DEFAULT_BASELINE  # noqa: E402
from learner.experiments.run_statistics import REPS, REPS_HELP, SEED, bootstrap_reps  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", type=Path, help="a bake-off's results.json")
    parser.add_argument("--out", type=Path, help="where to write (default: the results file's directory)")
    parser.add_argument("--baseline", choices=TEACHERS, default=DEFAULT_BASELINE, help=f"default {DEFAULT_BASELINE}")
    parser.add_argument("--reps", type=bootstrap_reps, default=REPS, help=REPS_HELP)
    parser.add_argument("--seed", type=int, default=SEED, help=f"the bootstrap's seed (default {SEED})")
    args = parser.parse_args()
    recompute_run_statistics(args.results, args.out, args.baseline, args.reps, args.seed)
    print(((args.out or args.results.parent) / RUN_STATISTICS_MARKDOWN).read_text(encoding="utf-8"))


if __name__ == "__main__":
    main()
