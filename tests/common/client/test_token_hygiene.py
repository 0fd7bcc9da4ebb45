"""The write token never shows in a repr, ``str`` or log line of the objects that hold it."""

from __future__ import annotations

import logging

from pydantic import SecretStr

from common.client.teacher_client import TeacherClient
from rollout_worker.actor import WorkerSettings
from teacher_service.core.config import Settings
from teacher_service.process import free_port

TOKEN = "hygiene-test-token-0123456789"


def _shown(thing: object) -> list[str]:
    return [repr(thing), str(thing), repr(getattr(thing, "__dict__", {}))]


def test_worker_settings_hide_the_token():
    settings = WorkerSettings("http://teacher:8000", "run", 4, 256, 1000, teacher_token=SecretStr(TOKEN))
    assert settings.teacher_token is not None and settings.teacher_token.get_secret_value() == TOKEN
    assert not [text for text in _shown(settings) if TOKEN in text]


def test_service_settings_hide_the_token():
    settings = Settings(teacher_token=TOKEN)
    assert not [text for text in _shown(settings) if TOKEN in text]


def test_the_client_hides_the_token_in_reprs_and_logs(caplog):
    """Against a port where nothing listens, so that the client logs its failures too."""
    caplog.set_level(logging.DEBUG)
    for token in (TOKEN, SecretStr(TOKEN)):
        client = TeacherClient(f"http://127.0.0.1:{free_port()}", "run", token=token, task_timeout=0.2)
        try:
            client.next_task()
        except Exception as error:
            assert TOKEN not in repr(error)
        shown = [*_shown(client), repr(client._http), repr(client._http.headers)]
        client.close(timeout=0.2)
        assert not [text for text in shown if TOKEN in text]
    assert caplog.records, "the client logged nothing to check"
    assert TOKEN not in caplog.text
