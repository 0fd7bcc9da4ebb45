from collections.abc import Callable, Iterator
from typing import Any

import httpx
import pytest
from spawned_processes import spawned_children

from common.client.schemas import ParameterSpec
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.process import ServiceProcess


@pytest.fixture(scope="session")
def write_token() -> str:
    return "service-test-token"


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory, write_token: str) -> Iterator[ServiceProcess]:
    """A real service on a free localhost port that guards writes with ``write_token``; a module's
    tests share it and each uses its own curricula."""
    db = tmp_path_factory.mktemp("teacher") / "teacher.db"
    with ServiceProcess(db, env={"KC_TEACHER_TOKEN": write_token}) as running:
        yield running


@pytest.fixture(scope="module")
def http(service: ServiceProcess, write_token: str) -> Iterator[httpx.Client]:
    """Talks to ``/api/v1`` with the write token."""
    headers = {"Authorization": f"Bearer {write_token}"}
    with httpx.Client(base_url=f"{service.url}/api/v1", headers=headers, timeout=30.0) as client:
        yield client


@pytest.fixture(scope="session")
def kuka_space() -> list[dict[str, Any]]:
    return [ParameterSpec.from_parameter(p).model_dump() for p in KUKA_TASK_SPACE.parameters]


@pytest.fixture(scope="session")
def fit_processes() -> Callable[[int], list[int]]:
    """Finds a service's fit processes: its multiprocessing children other than the resource tracker."""
    return spawned_children
