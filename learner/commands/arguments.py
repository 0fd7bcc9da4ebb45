"""Argument types and the usage error shared by the learner's sub-commands, kept free of heavy imports."""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from typing import Any

from common.client.schemas import TEACHER_KIND_PATTERN
from learner.core.config import TEACHERS


class UsageError(Exception):
    """Bad input or an unreachable service: reported in one line, exit code 2 (every command's ``run``)."""


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse type: a whole number (underscores allowed, as in 2_000_000) of at least ``minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text.replace("_", ""))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value

    return parse


def int_between(minimum: int, maximum: int) -> Callable[[str], int]:
    """An argparse type: a whole number from ``minimum`` to ``maximum``."""
    at_least = int_at_least(minimum)

    def parse(text: str) -> int:
        value = at_least(text)
        if value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum:_}, got {value:_}")
        return value

    return parse


positive_int = int_at_least(1)
non_negative_int = int_at_least(0)


def unit_fraction(text: str) -> float:
    """An argparse type: a number between 0 and 1."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number between 0 and 1, got {text!r}") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be between 0 and 1, got {value}")
    return value


def setting(text: str) -> tuple[str, Any]:
    """An argparse type: ``NAME=VALUE`` with VALUE in JSON (``fit_rate=100``, ``reward_range=[-5,10]``);
    a VALUE that is not JSON is taken as a string."""
    name, equals, value = text.partition("=")
    if not equals or not name.strip():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    try:
        return name.strip(), json.loads(value)
    except json.JSONDecodeError:
        return name.strip(), value


def add_override_flags(
    group: argparse._ArgumentGroup, scope: str, teacher_param: str = "a teacher parameter (e.g. fit_rate=100)"
) -> None:
    """``--teacher-param`` and ``--ppo`` (into ``teacher_params`` and ``ppo``): repeatable NAME=VALUE
    pairs; ``scope`` ends their help ('for this run', 'for every run'), ``teacher_param`` starts the first's."""
    for flag, dest, what in (
        ("--teacher-param", "teacher_params", teacher_param),
        ("--ppo", "ppo", "a PPO hyperparameter, a PPOConfig field in learner/core/config.py (e.g. entropy_coef=0.001)"),
    ):
        group.add_argument(
            flag,
            dest=dest,
            action="append",
            type=setting,
            default=[],
            metavar="NAME=VALUE",
            help=f"{what} {scope}, VALUE in JSON; repeatable",
        )


def teacher_kind(text: str) -> str:
    """A teacher kind's name, as the client's schemas shape it; which kinds exist is the service's to say."""
    if re.fullmatch(TEACHER_KIND_PATTERN, text) is None:
        raise argparse.ArgumentTypeError(f"{text!r} is not a teacher kind's name (such as {', '.join(TEACHERS[:3])})")
    return text


def add_teacher_flags(parser: argparse.ArgumentParser) -> None:
    """``--teacher KIND`` (any kind of the service's registry; alp-gmm by default) and repeatable
    ``--teacher-param NAME=VALUE`` (into ``teacher_params``), for the examples' own parsers."""
    parser.add_argument(
        "--teacher",
        type=teacher_kind,
        default="alp-gmm",
        metavar="KIND",
        help=f"the curriculum's teacher kind: {', '.join(TEACHERS)}",
    )
    parser.add_argument(
        "--teacher-param",
        dest="teacher_params",
        action="append",
        type=setting,
        default=[],
        metavar="NAME=VALUE",
        help="a parameter of the teacher kind, VALUE in JSON, on top of the example's defaults; repeatable "
        "(GET /api/v1/teachers lists each kind's parameters and bounds)",
    )


def run_command(
    command: str,
    body: Callable[[argparse.Namespace], int],
    args: argparse.Namespace,
    on_interrupt: str,
    failures: tuple[type[Exception], ...] = (),
) -> int:
    """Run a sub-command's ``body`` the way every command ends: a ``UsageError`` is one line on stderr
    and exit 2, one of ``failures`` (work that ran and failed) one line and exit 1, and Ctrl-C prints
    ``on_interrupt`` and exits 130, as a shell reports SIGINT."""
    try:
        return body(args)
    except UsageError as error:
        print(f"kuka-curriculum {command}: error: {error}", file=sys.stderr)
        return 2
    except failures as error:
        print(f"kuka-curriculum {command}: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"kuka-curriculum {command}: {on_interrupt}", file=sys.stderr)
        return 130
