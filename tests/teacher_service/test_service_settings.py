import argparse
from pathlib import Path

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
