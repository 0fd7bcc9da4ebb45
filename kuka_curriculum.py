"""The ``kuka-curriculum`` console script: the top of the import graph, which no package imports.

Each sub-command lives in the package that owns it. Its module is imported only when chosen (by a
plain import inside a loader, so the graph still shows the arrow), so ``serve`` starts without
loading torch and ``train`` without loading the web stack. A command module provides
``add_arguments(parser)`` and ``run(args) -> int``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from importlib import metadata
from typing import NamedTuple, Protocol


class CommandModule(Protocol):
    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def run(self, args: argparse.Namespace) -> int: ...


class Command(NamedTuple):
    summary: str
    load: Callable[[], CommandModule]


def _demo() -> CommandModule:
    from common.kuka import demo

    return demo


def _train() -> CommandModule:
    from learner.commands import train

    return train


def _serve() -> CommandModule:
    from teacher_service import cli

    return cli


def _evaluate() -> CommandModule:
    from learner.commands import evaluate

    return evaluate


def _render() -> CommandModule:
    from learner.commands import render

    return render


def _bakeoff() -> CommandModule:
    from learner.experiments import bakeoff

    return bakeoff


def _tune() -> CommandModule:
    from learner.experiments import tune

    return tune


def _control() -> CommandModule:
    from learner.commands import control

    return control


COMMANDS: dict[str, Command] = {
    "demo": Command("Write a short GIF of the KUKA grasp environment under random actions.", _demo),
    "train": Command("Train the PPO policy with distributed rollouts and a curriculum teacher.", _train),
    "serve": Command("Run the teacher service: curricula over HTTP, persisted in SQLite.", _serve),
    "evaluate": Command("Evaluate a checkpoint's deterministic policy, with 95% confidence intervals.", _evaluate),
    "render": Command("Write a GIF or MP4 of a checkpoint's policy at work.", _render),
    "bakeoff": Command(
        "Train and evaluate every teacher over several seeds; write a results table and curves.", _bakeoff
    ),
    "tune": Command("Search hyperparameters with Ray Tune, every trial a curriculum on one teacher service.", _tune),
    "control": Command("Drive the grasp environment by hand with sliders in pybullet's window.", _control),
}


def _version() -> str:
    """The installed distribution's version: pyproject.toml's, which is what pip and a bug report see."""
    try:
        return metadata.version("kuka-curriculum")
    except metadata.PackageNotFoundError:  # run from a checkout that was never installed
        return "(not installed)"


def _build_parser(chosen: str | None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="kuka-curriculum",
        description="Curriculum learning for a simulated KUKA grasping arm.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, command in COMMANDS.items():
        command_parser = sub.add_parser(name, help=command.summary.replace("%", "%%"), description=command.summary)
        if name == chosen:
            command.load().add_arguments(command_parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    chosen = next((a for a in argv if not a.startswith("-")), None)
    args = _build_parser(chosen if chosen in COMMANDS else None).parse_args(argv)
    return int(COMMANDS[args.command].load().run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
