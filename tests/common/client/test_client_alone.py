"""The teacher client as a distribution of its own (``client/``): its wheel is built from this checkout,
installed in a fresh virtual environment with nothing but its dependencies, and trains a toy environment
through ``CurriculumWrapper`` against a real teacher service, with no torch, Ray or PyBullet to be found.

The wheel is built as a user's ``python -m build`` would: an sdist first, the wheel from it, so both read
the code through ``client/common/client``, a symlink to ``common/client``. The environment is built with
pip (it may reach the package index for the four dependencies, at the lock's versions; pip's cache makes
reruns quick), so this module takes about half a minute.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tarfile
import tomllib
import zipfile
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from common.client.schemas import API_PREFIX
from common.client.write_token import TOKEN_VARIABLE
from teacher_service.process import ServiceProcess

ROOT = Path(__file__).resolve().parents[3]
CLIENT = ROOT / "client"
TOKEN = "client-alone-test-token"
PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*==\S+)")
CODE = sorted(path.name for path in (ROOT / "common" / "client").glob("*.py"))

SCRIPT = """
import importlib.metadata, importlib.util, json, sys

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
import common, common.client
report = {"issued": issued, "loaded": loaded, "importable": importable}
report["version"] = importlib.metadata.version("kuka-curriculum-client")
report["common_file"] = getattr(common, "__file__", None)
report["client_file"] = common.client.__file__
report["kuka"] = importlib.util.find_spec("common.kuka") is not None
print(json.dumps(report))
"""


def main_project() -> dict[str, object]:
    with (ROOT / "pyproject.toml").open("rb") as file:
        return dict(tomllib.load(file)["project"])


def client_project() -> dict[str, object]:
    with (CLIENT / "pyproject.toml").open("rb") as file:
        return dict(tomllib.load(file)["project"])


def test_the_client_distribution_has_the_main_packages_version_and_client_extra():
    main, client = main_project(), client_project()
    assert client["version"] == main["version"]
    assert client["dependencies"] == main["optional-dependencies"]["client"]  # type: ignore[index]


def test_the_client_distribution_reads_the_one_copy_of_the_code():
    link = CLIENT / "common" / "client"
    assert link.is_symlink(), "client/common/client is a link, not a second copy of the code"
    assert link.resolve() == ROOT / "common" / "client"
    assert not (CLIENT / "common" / "__init__.py").exists(), "common stays a namespace package in the client"


@pytest.fixture(scope="module")
def dist(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The client's sdist and wheel, built from the checkout as ``make client-wheel`` builds them."""
    out = tmp_path_factory.mktemp("client-dist")
    built = subprocess.run(
        [sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out), str(CLIENT)],
        capture_output=True,
        text=True,
    )
    assert built.returncode == 0, f"building the client failed:\n{built.stdout}\n{built.stderr}"
    return out


def test_the_sdist_and_the_wheel_hold_the_client_code_and_nothing_else(dist):
    (wheel,) = dist.glob("*.whl")
    (sdist,) = dist.glob("*.tar.gz")
    with zipfile.ZipFile(wheel) as archive:
        code = sorted(name for name in archive.namelist() if not name.split("/")[0].endswith(".dist-info"))
    assert code == [f"common/client/{name}" for name in CODE]
    with tarfile.open(sdist) as archive:
        members = {member.name.split("/", 1)[-1]: member for member in archive.getmembers()}
    assert all(members[f"common/client/{name}"].isfile() for name in CODE), "the sdist holds files, not the link"


def locked_pins() -> list[str]:
    """``name==version`` for each package of the dev lock, without hashes: a constraints file for pip."""
    lines = (ROOT / "requirements-dev.txt").read_text().splitlines()
    return [match.group(1) for match in map(PIN.match, lines) if match]


@pytest.fixture(scope="module")
def python(dist: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh virtual environment with the client's wheel and its dependencies at the lock's versions."""
    base = tmp_path_factory.mktemp("client-alone")
    venv, constraints = base / "venv", base / "constraints.txt"
    constraints.write_text("\n".join(locked_pins()) + "\n")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = venv / "bin" / "python"
    (wheel,) = dist.glob("*.whl")
    pip = subprocess.run(
        [str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check"]
        + ["--constraint", str(constraints), str(wheel)],
        capture_output=True,
        text=True,
    )
    assert pip.returncode == 0, f"installing the client wheel failed:\n{pip.stdout}\n{pip.stderr}"
    return python


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServiceProcess]:
    with ServiceProcess(tmp_path_factory.mktemp("teacher") / "teacher.db", env={TOKEN_VARIABLE: TOKEN}) as running:
        yield running


def test_the_client_wheel_alone_trains_through_the_teacher_without_torch_ray_or_pybullet(python, service, tmp_path):
    episodes = 7
    finished = subprocess.run(
        [str(python), "-c", SCRIPT, service.url, str(episodes)],
        capture_output=True,
        text=True,
        env={"PATH": str(python.parent), TOKEN_VARIABLE: TOKEN},
        cwd=tmp_path,  # not the checkout, whose common/ would shadow the installed one
        timeout=120,
    )
    assert finished.returncode == 0, finished.stderr
    report = json.loads(finished.stdout)
    assert report["loaded"] == [] and report["importable"] == [], f"the client environment has {report}"
    assert report["issued"] >= episodes
    assert report["version"] == main_project()["version"]
    assert Path(report["client_file"]).is_relative_to(python.parent.parent), "common.client is the installed one"
    assert report["common_file"] is None and not report["kuka"], "common is the client's namespace, nothing more"

    state = httpx.get(f"{service.url}{API_PREFIX}/curricula/alone/state", timeout=10).json()
    results = state["recent_results"]
    assert len(results) == episodes, "close() delivered every episode's result"
    assert all(result["length"] == round(result["params"]["steps"]) for result in results)
