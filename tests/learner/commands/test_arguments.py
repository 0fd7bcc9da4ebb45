"""The examples' teacher flags take every kind of the service's registry and refuse a name no kind could have
(a well-formed name the service lacks is the service's to refuse, with its message); a bounded count refuses
what lies outside its bounds."""

import argparse

import pytest

from learner.commands.arguments import add_teacher_flags, int_between
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


def test_a_bounded_count_takes_its_ends_and_refuses_beyond_them() -> None:
    parse = int_between(100, 100_000)
    assert (parse("100"), parse("100_000")) == (100, 100_000)
    for text, message in (("99", "at least 100"), ("100001", "at most 100_000"), ("1e4", "a whole number")):
        with pytest.raises(argparse.ArgumentTypeError, match=message):
            parse(text)
