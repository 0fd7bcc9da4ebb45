"""Success by block placement, pooled over ``evaluate --json`` files: the bake-off's placement table for
evaluations run by hand, e.g. the committed final policies of an earlier bake-off.

Files of one teacher are pooled into one row (a file written with ``--scripted`` adds its scripted
episodes to the scripted controller's row, as does a file of the scripted controller alone); every file
must have played the same episode seeds, so each row is read on the same placements.

    for k in 0 1 2 3 4; do .venv/bin/kuka-curriculum evaluate benchmarks/bakeoff-hard/bakeoff-v1/runs/currot-seed$k \\
        --episodes 100 --seed 100000 --json /tmp/currot-seed$k.json; done
    .venv/bin/kuka-curriculum evaluate --scripted --episodes 100 --seed 100000 --json /tmp/scripted.json
    .venv/bin/python bench/placement_bands.py /tmp/currot-seed*.json /tmp/scripted.json \\
        --plot /tmp/bands.png

A bake-off's own ``runs/<teacher>-seed<k>/evaluation.json.xz`` (read as it is: xz-compressed files are
read too) holds no ``teacher`` key: its directory names the teacher.

Prints the markdown table; ``--json`` also writes each row's band counts.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: the checkout's packages
from common.client.schemas import TEACHER_LABELS  # noqa: E402
from common.kuka.diagnostics import EpisodeDiagnostics  # noqa: E402
from learner.evaluation.checkpoint_evaluation import pooled_episodes  # noqa: E402
from learner.evaluation.episode_diagnostics import band_table, plot_bands  # noqa: E402
from learner.experiments.bakeoff_report import SCRIPTED_LABEL, counted, placement_record  # noqa: E402
from learner.experiments.bakeoff_runs import Run  # noqa: E402
from learner.experiments.run_archive import read_json  # noqa: E402

Rows = dict[str, list[list[tuple[EpisodeDiagnostics, bool]]]]
"""Per row label, each file's diagnosed episodes."""


def add(rows: Rows, label: str, data: dict[str, Any], source: Path, seeds: set[tuple[int, int]]) -> None:
    try:
        rows.setdefault(label, []).append(pooled_episodes(data, source, seeds))
    except ValueError as error:
        raise SystemExit(str(error)) from None


def teacher_of(data: dict[str, Any], source: Path) -> str:
    """The teacher an evaluation belongs to: its ``teacher`` key, else its bake-off run directory's name."""
    if "teacher" in data:
        return str(data["teacher"])
    run = Run.of_directory(source.resolve().parent)
    if run is None or run.teacher not in TEACHER_LABELS:
        raise SystemExit(
            f"{source}: names no teacher; give an evaluate --json file of a training run, or a bake-off's "
            "runs/<teacher>-seed<k>/evaluation.json.xz"
        )
    return run.teacher


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("files", nargs="+", type=Path, help="evaluate --json files (or their xz-compressed .json.xz)")
    parser.add_argument("--plot", type=Path, help="also draw the bars here (PNG)")
    parser.add_argument("--json", type=Path, help="also write each row's band counts here")
    args = parser.parse_args()
    rows: Rows = {}
    seeds: set[tuple[int, int]] = set()
    for path in args.files:
        data = read_json(path)
        if data.get("controller") == "scripted":
            add(rows, SCRIPTED_LABEL, data, path, seeds)
            continue
        teacher = teacher_of(data, path)
        add(rows, TEACHER_LABELS.get(teacher, teacher), data, path, seeds)
        if "scripted" in data:
            add(rows, SCRIPTED_LABEL, data["scripted"], path, seeds)
    pooled: list[tuple[str, list[tuple[EpisodeDiagnostics, bool]]]] = [
        (f"{label} ({counted(len(files), 'policy', 'policies')})", [pair for each in files for pair in each])
        for label, files in rows.items()
        if label != SCRIPTED_LABEL
    ]
    if SCRIPTED_LABEL in rows:
        # Deterministic on the same seeds, so every file holds the same scripted episodes: count them once.
        pooled.append((SCRIPTED_LABEL, rows[SCRIPTED_LABEL][0]))
    ((seed, episodes),) = seeds
    print(f"episode seeds {seed} to {seed + episodes - 1}\n")
    print("\n".join(band_table(pooled)))
    if args.plot is not None:
        plot_bands(args.plot, pooled)
    if args.json is not None:
        records = [
            {"row": label, "episodes": len(diagnosed), **placement_record(diagnosed)} for label, diagnosed in pooled
        ]
        args.json.write_text(
            json.dumps({"seed": seed, "episodes_per_file": episodes, "rows": records}, indent=2) + "\n"
        )


if __name__ == "__main__":
    main()
