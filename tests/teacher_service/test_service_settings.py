import argparse
import os
import subprocess
import sys
from pathlib import Path

import httpx
import pytest
from pydantic import ValidationError

from teacher_service.cli import add_arguments, settings_from
from teacher_service.process import ServiceProcess, free_port


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
    monkeypatch.setenv("KC_TEACHER_TOKEN", "s3cret-but-long-enough")
    settings = settings_from(_parse("--port", "9200"))
    assert settings.port == 9200
    assert settings.db == Path("/tmp/from-env.db")
    assert settings.teacher_token is not None and settings.teacher_token.get_secret_value() == "s3cret-but-long-enough"
    assert "s3cret" not in repr(settings) and "s3cret" not in str(settings)


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


MAKE_ONE = 'python3 -c "import secrets; print(secrets.token_urlsafe(32))"'


@pytest.mark.parametrize(
    ("token", "reason"),
    [
        ("change-me", "the placeholder from .env.example"),
        ("Change-Me ", "the placeholder from .env.example"),
        ("short-token", "has 11 characters, too few to be secret (at least 16)"),
    ],
)
def test_a_guessable_token_is_refused_with_how_to_make_one(monkeypatch, token, reason):
    monkeypatch.setenv("KC_TEACHER_TOKEN", token)
    with pytest.raises(ValidationError) as refused:
        settings_from(_parse())
    message = str(refused.value)
    assert reason in message and MAKE_ONE in message
    assert token.strip() not in message.replace("KC_TEACHER_TOKEN", ""), "the refusal must not echo the token"


def test_an_empty_token_means_none(monkeypatch):
    monkeypatch.setenv("KC_TEACHER_TOKEN", "")
    assert settings_from(_parse()).teacher_token is None


@pytest.mark.parametrize("token", ["change-me", "too-short"])
def test_serve_exits_with_the_reason_before_it_listens(tmp_path, token):
    port = free_port()
    result = subprocess.run(
        [sys.executable, "-m", "kuka_curriculum", "serve", "--port", str(port), "--db", str(tmp_path / "teacher.db")],
        env={**os.environ, "KC_TEACHER_TOKEN": token},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert result.stderr.startswith("kuka-curriculum serve: error: KC_TEACHER_TOKEN ")
    assert MAKE_ONE in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "teacher.db").exists()


def test_allowed_hosts_default_to_loopback_without_a_token_and_to_any_with_one(monkeypatch):
    monkeypatch.delenv("KC_ALLOWED_HOSTS", raising=False)
    monkeypatch.delenv("KC_TEACHER_TOKEN", raising=False)
    assert settings_from(_parse()).host_names() == ["localhost", "127.0.0.1", "[::1]"]
    monkeypatch.setenv("KC_TEACHER_TOKEN", "a-token-long-enough-to-keep")
    assert settings_from(_parse()).host_names() == ["*"]


@pytest.mark.parametrize(
    ("value", "names"),
    [
        ("teacher, 127.0.0.1,Teacher.Lab.example", ["teacher", "127.0.0.1", "teacher.lab.example"]),
        ('["teacher", "::1", "*.lab.example"]', ["teacher", "[::1]", "*.lab.example"]),
        ("*", ["*"]),
    ],
)
def test_allowed_hosts_read_a_comma_separated_or_json_list(monkeypatch, value, names):
    monkeypatch.setenv("KC_ALLOWED_HOSTS", value)
    assert settings_from(_parse()).host_names() == names


@pytest.mark.parametrize(
    ("env", "answered", "refused"),
    [
        ({}, ["127.0.0.1:{port}", "localhost:{port}", "LOCALHOST", "[::1]:{port}"], ["attacker.example:{port}", ""]),
        ({"KC_TEACHER_TOKEN": "a-token-long-enough-to-keep"}, ["attacker.example:{port}", "teacher:8000"], []),
        (
            {"KC_ALLOWED_HOSTS": "127.0.0.1,teacher,*.lab.example"},
            ["teacher:{port}", "gpu1.lab.example", "127.0.0.1"],
            ["localhost:{port}", "lab.example", "attacker.example"],
        ),
    ],
)
def test_requests_for_other_host_names_get_400(tmp_path, env, answered, refused):
    with ServiceProcess(tmp_path / "teacher.db", env=env) as service:
        for host in answered:
            for path in ("/healthz", "/api/v1/curricula", "/"):
                response = httpx.get(f"{service.url}{path}", headers={"Host": host.format(port=service.port)})
                assert response.status_code == 200, (host, path, response.text)
        for host in refused:
            response = httpx.get(f"{service.url}/api/v1/curricula", headers={"Host": host.format(port=service.port)})
            assert response.status_code == 400, (host, response.text)
            assert "KC_ALLOWED_HOSTS" in response.json()["detail"]
