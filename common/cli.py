"""The ``kuka-curriculum`` console script.

Each sub-command lives in the package that owns it and is imported only when chosen, so
``serve`` starts without loading torch and ``train`` without loading the web stack. A command
module provides ``add_arguments(parser)`` and ``run(args) -> int``.
"""

from __future__ import annotations

import argparse
import importlib
import sys

COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("common.demo", "Write a short GIF of the KUKA grasp environment under random actions."),
    "train": ("learner.cli", "Train the PPO policy with distributed rollouts and a curriculum teacher."),
    "serve": ("teacher_service.cli", "Run the teacher service: curricula over HTTP, persisted in SQLite."),
    "evaluate": ("learner.evaluate", "Evaluate a checkpoint's deterministic policy, with 95% confidence intervals."),
    "render": ("learner.render", "Write a GIF or MP4 of a checkpoint's policy at work."),
    "bakeoff": (
        "learner.bakeoff",
        "Train and evaluate every teacher over several seeds; write a results table and curves.",
    ),
}


def _build_parser(chosen: str | None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="kuka-curriculum",
        description="Curriculum learning for a simulated KUKA grasping arm.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module_path, summary) in COMMANDS.items():
        command_parser = sub.add_parser(name, help=summary.replace("%", "%%"), description=summary)
        if name == chosen:
            importlib.import_module(module_path).add_arguments(command_parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    chosen = next((a for a in argv if not a.startswith("-")), None)
    args = _build_parser(chosen if chosen in COMMANDS else None).parse_args(argv)
    module = importlib.import_module(COMMANDS[args.command][0])
    return int(module.run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
