"""Lever 5 of issue 80, read on finished runs: each run's validated policy, scored on a screen's episodes.

For each run directory, its candidate checkpoints (``learner.evaluation.selection``: from half the budget on,
every twelfth of it, the first checkpoint at or after each mark, 3.0, 3.5, ... 5.5M steps of 6M; and the final
one) each play the validation episodes (200 hardest-point episodes from seed 200,000, deterministic, as
``kuka-curriculum evaluate`` plays them); the best is the run's policy, and it plays the screening episodes
(500 from seed 20,000). Writes, per run, ``<out>/<run>/validation.json`` (every candidate's validation success
and the choice) and ``<out>/<run>/evaluation-hardest.json.xz`` (the chosen policy's screening evaluation in
``evaluate --json``'s format, which ``bench/screen_report.py`` reads). A run whose files exist is skipped, so
the command can be stopped and run again. ``train --policy-choice validated`` makes the same choice in a run.

    .venv/bin/python bench/select_checkpoint.py /work/wt-i80/runs/hard-screen-v1/currot-i80-steady-seed10{0,1,2,3} \\
        --out benchmarks/bakeoff-hard/screening/i80-validated
"""

from __future__ import annotations

import argparse
import datetime
import json
import lzma
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.provenance import commit, machine  # noqa: E402
from learner.commands.arguments import int_between, positive_int  # noqa: E402
from learner.commands.checkpoint_arguments import checkpoint_task  # noqa: E402
from learner.core.checkpoint import Checkpoint, load_checkpoint  # noqa: E402
from learner.evaluation.checkpoint_evaluation import (  # noqa: E402
    EvaluationResult,
    checkpoint_record,
    evaluate_checkpoint,
)
from learner.evaluation.selection import (  # noqa: E402
    VALIDATION_EPISODES,
    VALIDATION_SEED,
    Validated,
    choice_record,
    choose,
    run_schedule,
    validate,
)

SCREENING_SEED = 20_000
SCREENING_EPISODES = 500
MAX_EPISODES = 5_000
"""The most episodes one evaluation may play (about 20 minutes of the machine a thousand)."""


def play(checkpoint: Checkpoint, episodes: int, seed: int, processes: int | None) -> EvaluationResult:
    """The checkpoint's deterministic policy on its family's evaluation task, as ``evaluate`` plays it."""
    task = checkpoint_task("hardest", checkpoint)
    return evaluate_checkpoint(checkpoint, task, episodes, seed, processes, progress=False)


def validate_run(run_dir: Path, out: Path, args: argparse.Namespace) -> dict[str, Any]:
    """Choose the run's policy on the validation episodes, score it on the screening ones, and write both."""
    first_step, every = run_schedule(run_dir)
    first_step, every = args.first_step or first_step, args.every or every
    loaded: dict[Path, Checkpoint] = {}

    def success(path: Path) -> float:
        loaded[path] = load_checkpoint(path)
        return play(loaded[path], args.validation_episodes, args.validation_seed, args.processes).success_rate.estimate

    def on_candidate(candidate: Validated) -> None:
        print(f"{run_dir.name}: {candidate.path.name} validation {candidate.success:.1%}", flush=True)

    validated = validate(run_dir, first_step, every, success, on_candidate)
    chosen = choose(validated)
    checkpoint = loaded[chosen.path]
    screening = play(checkpoint, args.screening_episodes, args.screening_seed, args.processes)
    out.mkdir(parents=True, exist_ok=True)
    with lzma.open(out / "evaluation-hardest.json.xz", "wt", encoding="utf-8") as file:
        json.dump(checkpoint_record(checkpoint, screening), file)
    summary = {
        "run": str(run_dir),
        "generated": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "commit": commit(),
        "machine": machine(),
        **choice_record(run_dir, validated, chosen, args.validation_episodes, args.validation_seed, first_step, every),
        "screening": {
            "episodes": args.screening_episodes,
            "seed": args.screening_seed,
            "success_rate": screening.success_rate.to_dict(),
        },
    }
    (out / "validation.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return summary


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", type=Path, nargs="+", help="finished run directories")
    parser.add_argument("--out", type=Path, required=True, help="one folder per run is written here")
    parser.add_argument("--first-step", type=positive_int, help="default: half the run's budget (learner's schedule)")
    parser.add_argument("--every", type=positive_int, help="default: a twelfth of the run's budget")
    parser.add_argument(
        "--validation-episodes", type=int_between(1, MAX_EPISODES), default=VALIDATION_EPISODES, help="default 200"
    )
    parser.add_argument("--validation-seed", type=int, default=VALIDATION_SEED, help=f"default {VALIDATION_SEED:_}")
    parser.add_argument(
        "--screening-episodes", type=int_between(1, MAX_EPISODES), default=SCREENING_EPISODES, help="default 500"
    )
    parser.add_argument("--screening-seed", type=int, default=SCREENING_SEED, help=f"default {SCREENING_SEED:_}")
    parser.add_argument("--processes", type=positive_int, help="evaluation processes (default: one per CPU)")
    args = parser.parse_args(argv)
    for run_dir in args.runs:
        out = args.out / run_dir.name
        if (out / "validation.json").exists() and (out / "evaluation-hardest.json.xz").exists():
            print(f"{run_dir.name}: done before, skipped")
            continue
        summary = validate_run(run_dir, out, args)
        score = summary["screening"]["success_rate"]["estimate"]
        print(f"{run_dir.name}: chose {summary['chosen']}, screening {score:.1%}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
