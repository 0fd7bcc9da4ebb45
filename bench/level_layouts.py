"""How many distinct layouts a level family's training set and held-out set hold, and how many held-out
layouts occur among the training levels: is a "held-out" level a layout the student has not trained on?

A layout is a level's initial grid with the agent's start pose (``common.levels.layouts``); the grid alone
is counted too. The training set is the levels 0 to ``--levels`` - 1 (``train --levels``), the held-out set
the evaluations' seeds from 1,000,000 (``common.families.base.held_out_seeds``).

    .venv/bin/python bench/level_layouts.py --env MiniGrid-DoorKey-8x8-v0 MiniGrid-Gamut-v0 \\
        --levels 500 --held-out 100
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from common.families.base import held_out_seeds
from common.levels import LEVEL_ENV_IDS
from common.levels.layouts import level_layouts


def count_layouts(env_id: str, levels: int, held_out: int) -> dict[str, Any]:
    """The counts for one family: distinct layouts (with the start pose, and grids alone) in each set, and
    the held-out levels whose layout (grid) is also a training level's."""
    training = level_layouts(env_id, range(levels))
    evaluated = level_layouts(env_id, held_out_seeds(held_out))
    training_poses = {layout.with_pose for layout in training}
    training_grids = {layout.grid for layout in training}
    return {
        "env": env_id,
        "training_levels": levels,
        "training_layouts": len(training_poses),
        "training_grids": len(training_grids),
        "held_out_levels": held_out,
        "held_out_layouts": len({layout.with_pose for layout in evaluated}),
        "held_out_grids": len({layout.grid for layout in evaluated}),
        "held_out_layouts_in_training": sum(layout.with_pose in training_poses for layout in evaluated),
        "held_out_grids_in_training": sum(layout.grid in training_grids for layout in evaluated),
    }


def table(rows: list[dict[str, Any]]) -> str:
    """The counts as a Markdown table, one row per family."""
    lines = [
        "| env | training levels | distinct layouts (grids) | held-out levels | distinct layouts (grids) "
        "| held-out layouts in training (grids) |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['env']} | {row['training_levels']:,} | {row['training_layouts']:,} ({row['training_grids']:,}) "
            f"| {row['held_out_levels']:,} | {row['held_out_layouts']:,} ({row['held_out_grids']:,}) "
            f"| {row['held_out_layouts_in_training']:,} ({row['held_out_grids_in_training']:,}) |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", nargs="+", choices=LEVEL_ENV_IDS, required=True, help="level families to count")
    parser.add_argument("--levels", type=int, default=500, help="training levels, 0 to LEVELS - 1 (default 500)")
    parser.add_argument("--held-out", type=int, default=100, help="held-out levels from seed 1,000,000 (default 100)")
    parser.add_argument("--json", action="store_true", help="print the counts as JSON instead of a table")
    args = parser.parse_args(argv)
    rows = [count_layouts(env_id, args.levels, args.held_out) for env_id in args.env]
    print(json.dumps(rows, indent=2) if args.json else table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
