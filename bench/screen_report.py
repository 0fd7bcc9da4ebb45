"""A screen's report: each arm's runs read from their final evaluations, the screen's test and the rliable figures.

A screen (docs/results/student.md) scores every run's policy (its final one, or its validated one as a second
arm) on one fixed set of hardest-point episodes and calls a run good at ``--threshold`` or more. This reads
those evaluation files (plain or xz-compressed JSON, as ``kuka-curriculum evaluate`` and the screen script write
them), checks that every run played the same episodes (the same count and first seed), and reports per arm:

- the screen's test: the good runs against the baseline arm's, Fisher's exact test, one-sided;
- the rliable figures (``learner.experiments.run_statistics``): IQM and mean with stratified-bootstrap
  intervals, the share of good runs with its Wilson interval, P(improvement over the baseline);
- a performance profile.

Writes ``results.json`` (every run's file and score, the test, the figures), ``results.md`` and
``performance_profile.png`` to ``--out``. Seconds, most of it the bootstrap.

    .venv/bin/python bench/screen_report.py --out benchmarks/bakeoff-hard/screening/i80-screen1 --baseline baseline \\
        --arm "baseline=benchmarks/bakeoff-hard/screening/i80-baseline/*.json.xz" \\
        --arm "steady=benchmarks/bakeoff-hard/screening/hard-v1-currot-i80-steady-seed*/evaluation-hardest.json.xz"
"""

from __future__ import annotations

import argparse
import datetime
import glob
import json
import lzma
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.provenance import commit, machine  # noqa: E402
from bench.screen_power import fisher_one_sided  # noqa: E402
from learner.experiments.run_statistics import (  # noqa: E402
    REPS,
    REPS_HELP,
    SEED,
    THRESHOLD,
    bootstrap_reps,
    plot_performance_profile,
    run_statistics,
    statistics_table,
)

MAX_ARMS = 12
MAX_RUNS_PER_ARM = 200
"""Bounds on what one report reads: a screen has a few arms of ten or so runs."""


class ScreenError(ValueError):
    """Evaluation files that cannot make one screen: none found, unreadable, or played on other episodes."""


@dataclass(frozen=True)
class RunScore:
    path: Path
    score: float
    episodes: int
    first_seed: int


def read_run(path: Path) -> RunScore:
    """A run's hardest-point success rate, and the episodes it was measured on, from its evaluation file."""
    opener = lzma.open if path.suffix == ".xz" else open
    try:
        with opener(path, "rt", encoding="utf-8") as file:
            evaluation = json.load(file)
        return RunScore(
            path, float(evaluation["success_rate"]["estimate"]), int(evaluation["episodes"]), int(evaluation["seed"])
        )
    except (OSError, ValueError, KeyError, TypeError, lzma.LZMAError) as error:
        raise ScreenError(f"{path}: not an evaluation file ({type(error).__name__}: {error})") from None


def read_arms(patterns: Mapping[str, Sequence[str]]) -> dict[str, list[RunScore]]:
    """Each arm's runs from its glob patterns (sorted by path, each file once); every run must have played the
    same episodes as every other, since a run near the bar is good or not by the episode set."""
    arms: dict[str, list[RunScore]] = {}
    for arm, arm_patterns in patterns.items():
        paths = sorted({Path(found) for pattern in arm_patterns for found in glob.glob(pattern)})
        if not paths:
            raise ScreenError(f"arm {arm!r}: no file matches {', '.join(arm_patterns)}")
        if len(paths) > MAX_RUNS_PER_ARM:
            raise ScreenError(f"arm {arm!r}: {len(paths)} files, at most {MAX_RUNS_PER_ARM}")
        arms[arm] = [read_run(path) for path in paths]
    episode_sets = {(run.episodes, run.first_seed) for runs in arms.values() for run in runs}
    if len(episode_sets) > 1:
        found = ", ".join(f"{episodes} from seed {seed}" for episodes, seed in sorted(episode_sets))
        raise ScreenError(f"the runs played different episodes ({found}); a screen scores every run on one set")
    return arms


def screen_report(
    arms: Mapping[str, Sequence[RunScore]], baseline: str, threshold: float, reps: int, seed: int
) -> dict[str, Any]:
    """The report as JSON-ready data: each run, each arm's test against the baseline, and the rliable figures."""
    if baseline not in arms:
        raise ScreenError(f"baseline {baseline!r} is not among the arms ({', '.join(arms)})")
    scores = {arm: [run.score for run in runs] for arm, runs in arms.items()}
    figures = run_statistics(scores, baseline, threshold, reps, seed)
    good = {arm: sum(score >= threshold for score in values) for arm, values in scores.items()}
    tests = {
        arm: {
            "good_runs": good[arm],
            "runs": len(values),
            "fisher_one_sided_p": fisher_one_sided(good[arm], len(values), good[baseline], len(scores[baseline])),
        }
        for arm, values in scores.items()
        if arm != baseline
    }
    any_run = next(iter(arms.values()))[0]
    return {
        "episodes": any_run.episodes,
        "first_episode_seed": any_run.first_seed,
        "threshold": threshold,
        "baseline": baseline,
        "runs": {arm: [{"file": str(run.path), "score": run.score} for run in runs] for arm, runs in arms.items()},
        "tests": tests,
        "run_statistics": figures.to_dict(),
        "table": statistics_table(figures),
    }


def markdown(report: Mapping[str, Any]) -> str:
    lines = [
        f"# Screen report: {', '.join(report['runs'])}",
        "",
        f"Each run's policy (the one its evaluation file played) on {report['episodes']} hardest-point episodes "
        f"from seed {report['first_episode_seed']}; a run is good at {report['threshold']:.0%} or more.",
        "",
        f"| Arm | Good runs | Fisher's exact test against {report['baseline']}, one-sided |",
        "|---|---|---|",
    ]
    baseline_runs = report["runs"][report["baseline"]]
    baseline_good = sum(run["score"] >= report["threshold"] for run in baseline_runs)
    lines.append(f"| {report['baseline']} (the baseline) | {baseline_good} of {len(baseline_runs)} | — |")
    for arm, test in report["tests"].items():
        lines.append(f"| {arm} | {test['good_runs']} of {test['runs']} | p = {test['fisher_one_sided_p']:.3f} |")
    statistics = report["run_statistics"]
    lines += ["", f"By rliable ({statistics['reps']:,} bootstrap resamples, seed {statistics['seed']}):", ""]
    lines += report["table"]
    lines += ["", "Per run:", ""]
    for arm, runs in report["runs"].items():
        scores = ", ".join(f"{run['score']:.1%}" for run in runs)
        lines.append(f"- {arm}: {scores}")
    lines += ["", "![performance profile](performance_profile.png)", ""]
    return "\n".join(lines)


def parse_arm(text: str) -> tuple[str, str]:
    name, equals, pattern = text.partition("=")
    if not equals or not name or not pattern:
        raise argparse.ArgumentTypeError(f"expected NAME=GLOB, got {text!r}")
    return name, pattern


def unit_threshold(text: str) -> float:
    value = float(text)
    if not 0.0 < value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be in (0, 1], got {text}")
    return value


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--arm", type=parse_arm, action="append", required=True, help="NAME=GLOB, repeatable")
    parser.add_argument("--baseline", required=True, help="the arm every other is tested against")
    parser.add_argument("--out", type=Path, required=True, help="where results.json, results.md and the plot go")
    parser.add_argument(
        "--threshold", type=unit_threshold, default=THRESHOLD, help=f"a good run's score (default {THRESHOLD})"
    )
    parser.add_argument("--reps", type=bootstrap_reps, default=REPS, help=REPS_HELP)
    args = parser.parse_args(argv)
    patterns: dict[str, list[str]] = {}
    for name, pattern in args.arm:
        patterns.setdefault(name, []).append(pattern)
    if len(patterns) > MAX_ARMS:
        parser.error(f"at most {MAX_ARMS} arms, got {len(patterns)}")
    try:
        arms = read_arms(patterns)
        report = screen_report(arms, args.baseline, args.threshold, args.reps, SEED)
    except ScreenError as error:
        parser.exit(2, f"screen_report: {error}\n")
    report = {
        "generated": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "command": " ".join(sys.argv if argv is None else ["bench/screen_report.py", *argv]),
        "commit": commit(),
        "machine": machine(),
        **report,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.json").write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    (args.out / "results.md").write_text(markdown(report), encoding="utf-8")
    scores = {arm: [run["score"] for run in runs] for arm, runs in report["runs"].items()}
    plot_performance_profile(args.out / "performance_profile.png", scores, reps=args.reps, seed=SEED)
    print((args.out / "results.md").read_text(encoding="utf-8"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
