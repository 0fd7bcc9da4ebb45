"""Success by how the block lies turned and how near the arm, from ``evaluate --json`` files: where a
policy misses that the placement bands (``bench/placement_bands.py``, by distance beyond the clamp) do not
separate.

A block looks the same turned half a turn, so its yaw is read modulo a half turn, in [-90, 90) degrees:
"clockwise" below 0 (seen from above), "anticlockwise" from 0. Its x is cut into bands from the arm
outwards; near the arm (x < 0.6) the hardest point's blocks lie at large y, beside the tray's wall. Each
file is one column (its run directory's name, or the file's): success (episodes), the median distance
from the gripper's axis to the block at touchdown, and where the file recorded it, the median turn of the
wrist at touchdown (signed as the yaw actions add up).

    .venv/bin/python bench/success_by_turn.py \\
        benchmarks/bakeoff-hard/*/runs/currot-seed0/evaluation.json.xz /tmp/scripted.json
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: the checkout's packages
from common.kuka.diagnostics import EpisodeDiagnostics  # noqa: E402
from learner.evaluation.checkpoint_evaluation import pooled_episodes  # noqa: E402
from learner.experiments.run_archive import EVALUATION_FILE, SUFFIX, read_json  # noqa: E402

X_BANDS = ((-math.inf, 0.5), (0.5, 0.6), (0.6, 0.65), (0.65, math.inf))
"""Block x (metres) bands: below the IK target's x range, its near half, its far half, and beyond it."""


def turn_sense(block_yaw: float) -> str:
    """'clockwise' or 'anticlockwise': the sign of the block's yaw modulo a half turn, in [-pi/2, pi/2)."""
    return "clockwise" if (block_yaw + math.pi / 2) % math.pi - math.pi / 2 < 0 else "anticlockwise"


def band_name(low: float, high: float) -> str:
    if math.isinf(low):
        return f"x < {high:g}"
    if math.isinf(high):
        return f"x ≥ {low:g}"
    return f"{low:g} ≤ x < {high:g}"


def cell(episodes: Sequence[tuple[EpisodeDiagnostics, bool]]) -> str:
    """'successes% (episodes), offset cm[, wrist deg]' for one group of episodes; '—' for none."""
    if not episodes:
        return "—"
    successes = sum(success for _, success in episodes)
    text = f"{100 * successes / len(episodes):.0f}% ({len(episodes)})"
    offsets = [each.touchdown_offset for each, _ in episodes if each.touchdown_offset is not None]
    if offsets:
        text += f", {100 * float(np.median(offsets)):.1f} cm"
    turns = [each.touchdown_wrist_turn_degrees for each, _ in episodes if each.touchdown_wrist_turn_degrees is not None]
    if turns:
        text += f", wrist {float(np.median(turns)):+.0f}°"
    return text


def table(columns: dict[str, list[tuple[EpisodeDiagnostics, bool]]]) -> list[str]:
    """The markdown table: a row per turn sense and x band, a column per file, then the whole."""
    lines = ["| block | " + " | ".join(columns) + " |", "|---|" + "---|" * len(columns)]
    for sense in ("clockwise", "anticlockwise"):
        for low, high in X_BANDS:
            cells = [
                cell(
                    [
                        (each, ok)
                        for each, ok in diagnosed
                        if turn_sense(each.block_yaw) == sense and low <= each.block_x < high
                    ]
                )
                for diagnosed in columns.values()
            ]
            lines.append(f"| {sense}, {band_name(low, high)} | " + " | ".join(cells) + " |")
    lines.append("| all | " + " | ".join(cell(diagnosed) for diagnosed in columns.values()) + " |")
    return lines


def label(path: Path, data: dict[str, object]) -> str:
    if data.get("controller") == "scripted":
        return "scripted controller"
    return path.parent.name if path.name in (EVALUATION_FILE, EVALUATION_FILE + SUFFIX) else path.stem


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "files", nargs="+", type=Path, help="evaluate --json files (or .json.xz), all of the same episode seeds"
    )
    args = parser.parse_args(argv)
    columns: dict[str, list[tuple[EpisodeDiagnostics, bool]]] = {}
    seeds: set[tuple[int, int]] = set()
    for path in args.files:
        data = read_json(path)
        try:
            diagnosed = pooled_episodes(data, path, seeds)
        except ValueError as error:
            raise SystemExit(str(error)) from None
        name = label(path, data)
        columns[str(path) if name in columns else name] = diagnosed
    ((seed, episodes),) = seeds
    print(f"episode seeds {seed} to {seed + episodes - 1}; each cell: success (episodes), median touchdown offset\n")
    print("\n".join(table(columns)))


if __name__ == "__main__":
    main()
