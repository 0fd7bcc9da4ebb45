"""A real teacher service for each example test, guarding writes with the token the examples get."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from example_runner import TOKEN

from common.client.curriculum_wrapper import TOKEN_VARIABLE
from teacher_service.process import ServiceProcess


@pytest.fixture
def teacher(tmp_path: Path) -> Iterator[ServiceProcess]:
    """A service of the test's own (tests may kill and restart it)."""
    with ServiceProcess(tmp_path / "teacher" / "teacher.db", env={TOKEN_VARIABLE: TOKEN}) as running:
        yield running
