"""The examples' teacher flags take every kind of the service's registry and refuse a name no kind could have
(a well-formed name the service lacks is the service's to refuse, with its message)."""

import argparse

import pytest

from learner.commands.arguments import add_teacher_flags
from teacher_service.teachers import TEACHER_KINDS


def example_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(exit_on_error=False)
    add_teacher_flags(parser)
    return parser


@pytest.mark.parametrize("kind", sorted(TEACHER_KINDS))
def test_every_registered_kind_is_a_teacher_choice(kind: str) -> None:
    assert example_parser().parse_args(["--teacher", kind, "--teacher-param", "seed_like=3"]).teacher == kind


def test_a_name_no_kind_could_have_is_refused_and_the_default_is_alp_gmm() -> None:
    assert example_parser().parse_args([]).teacher == "alp-gmm"
    with pytest.raises(argparse.ArgumentError, match="'Not a kind' is not a teacher kind's name"):
        example_parser().parse_args(["--teacher", "Not a kind"])
