import argparse
from pathlib import Path

import pytest
from pydantic import ValidationError

from teacher_service.cli import add_arguments, settings_from


def _parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return parser.parse_args(argv)


def test_defaults_keep_the_service_private():
    settings = settings_from(_parse())
    assert settings.host == "127.0.0.1" and settings.port == 8000
    assert settings.teacher_token is None and settings.sqlite_synchronous == "FULL"


def test_flags_override_environment_which_overrides_defaults(monkeypatch):
    monkeypatch.setenv("KC_PORT", "9100")
    monkeypatch.setenv("KC_DB", "/tmp/from-env.db")
    monkeypatch.setenv("KC_TEACHER_TOKEN", "s3cret")
    settings = settings_from(_parse("--port", "9200"))
    assert settings.port == 9200
    assert settings.db == Path("/tmp/from-env.db")
    assert settings.teacher_token is not None and settings.teacher_token.get_secret_value() == "s3cret"
    assert "s3cret" not in repr(settings)


def test_fit_settings_come_from_flags_or_environment_within_their_bounds(monkeypatch):
    assert (settings_from(_parse()).fit_processes, settings_from(_parse()).fit_timeout_s) == (2, 60.0)
    monkeypatch.setenv("KC_FIT_PROCESSES", "3")
    monkeypatch.setenv("KC_FIT_TIMEOUT_S", "90")
    settings = settings_from(_parse("--fit-timeout", "120"))
    assert (settings.fit_processes, settings.fit_timeout_s) == (3, 120.0)
    for flags in (
        ["--fit-processes", "0"],
        ["--fit-processes", "9"],
        ["--fit-timeout", "0.5"],
        ["--fit-timeout", "4000"],
    ):
        with pytest.raises(ValidationError):
            settings_from(_parse(*flags))
