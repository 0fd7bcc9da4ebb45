"""``common.client`` works with nothing but its own dependencies: a fresh virtual environment gets only
the ``client`` extra's requirements and a copy of ``common/__init__.py`` and ``common/client/``, then
trains a toy environment through ``CurriculumWrapper`` against a real teacher service.

The environment is built with pip (it may reach the package index; pip's cache makes reruns quick),
so this module takes about half a minute.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from common.client.schemas import API_PREFIX
from common.client.write_token import TOKEN_VARIABLE
from teacher_service.process import ServiceProcess

ROOT = Path(__file__).resolve().parents[3]
TOKEN = "client-alone-test-token"
HEAVY = ("torch", "ray", "pybullet")

SCRIPT = """
import importlib.util, json, sys

import gymnasium
import numpy as np

from common.client.curriculum_wrapper import CurriculumRegistration, CurriculumWrapper
from common.client.task_space import Parameter, TaskSpace
from common.client.teacher_client import TeacherClient

SPACE = TaskSpace([Parameter("steps", 1.0, 5.0, hardest=5.0, easiest=1.0)])


class Count(gymnasium.Env):
    observation_space = gymnasium.spaces.Box(0.0, 10.0, shape=(1,))
    action_space = gymnasium.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.left = round(options["task"]["steps"])
        return np.zeros(1, dtype=np.float32), {}

    def step(self, action):
        self.left -= 1
        return np.zeros(1, dtype=np.float32), 1.0, self.left == 0, False, {"is_success": True}


url, episodes = sys.argv[1], int(sys.argv[2])
env = CurriculumWrapper(Count(), url, "alone", register=CurriculumRegistration("random", SPACE, seed=1))
for _ in range(episodes):
    env.reset()
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        done = terminated or truncated
env.close()
with TeacherClient(url, "alone") as client:
    issued = client.info().counters.tasks_issued
loaded = sorted({name.split(".")[0] for name in sys.modules} & {"torch", "ray", "pybullet"})
importable = [name for name in ("torch", "ray", "pybullet") if importlib.util.find_spec(name) is not None]
print(json.dumps({"issued": issued, "loaded": loaded, "importable": importable}))
"""


def client_requirements() -> list[str]:
    with (ROOT / "pyproject.toml").open("rb") as file:
        return list(tomllib.load(file)["project"]["optional-dependencies"]["client"])


@pytest.fixture(scope="module")
def alone(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A virtual environment with the client extra only, and a folder holding only the client's code."""
    base = tmp_path_factory.mktemp("client-alone")
    venv, code = base / "venv", base / "code"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = venv / "bin" / "python"
    install = [str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check"]
    pip = subprocess.run(
        [*install, "--constraint", str(ROOT / "constraints.txt"), *client_requirements()],
        capture_output=True,
        text=True,
    )
    assert pip.returncode == 0, f"installing the client extra failed:\n{pip.stdout}\n{pip.stderr}"
    package = code / "common"
    package.mkdir(parents=True)
    shutil.copy(ROOT / "common" / "__init__.py", package / "__init__.py")
    shutil.copytree(ROOT / "common" / "client", package / "client", ignore=shutil.ignore_patterns("__pycache__"))
    return python, code


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServiceProcess]:
    with ServiceProcess(tmp_path_factory.mktemp("teacher") / "teacher.db", env={TOKEN_VARIABLE: TOKEN}) as running:
        yield running


def test_the_client_extra_alone_trains_through_the_teacher_without_torch_ray_or_pybullet(alone, service):
    python, code = alone
    episodes = 7
    environment = {"PATH": str(python.parent), "PYTHONPATH": str(code), TOKEN_VARIABLE: TOKEN}
    finished = subprocess.run(
        [str(python), "-c", SCRIPT, service.url, str(episodes)],
        capture_output=True,
        text=True,
        env=environment,
        cwd=code,
        timeout=120,
    )
    assert finished.returncode == 0, finished.stderr
    report = json.loads(finished.stdout)
    assert report["loaded"] == [] and report["importable"] == [], f"the client environment has {report}"
    assert report["issued"] >= episodes

    state = httpx.get(f"{service.url}{API_PREFIX}/curricula/alone/state", timeout=10).json()
    results = state["recent_results"]
    assert len(results) == episodes, "close() delivered every episode's result"
    assert all(result["length"] == round(result["params"]["steps"]) for result in results)
