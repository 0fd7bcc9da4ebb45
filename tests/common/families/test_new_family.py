"""Adding a task family is one module and its line in the registry: a copy of the packages gains a toy family
that way, and the copy's ``kuka-curriculum`` trains on it, with its own teacher service and Ray, and evaluates
the checkpoint, with no other file touched."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.package_copies import changed_files, copies_before_and_after

ROOT = Path(__file__).resolve().parents[3]
PACKAGES = ("common", "teacher_service", "rollout_worker", "learner")
REGISTRY = Path("common/families/__init__.py")
TOY_MODULE = Path("common/families/toy.py")

TOY_SOURCE = '''"""A toy family for the registry test: move a point onto a target the task sets."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from common.client.task_space import Parameter, TaskSpace
from common.families.base import PolicyShape, TaskFamily


class ToyEnv(gym.Env[np.ndarray, np.ndarray]):
    observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.target, self.steps = float(((options or {}).get("task") or {}).get("target", 1.0)), 0
        return np.array([self.target], np.float32), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.steps += 1
        miss = abs(float(action[0]) - self.target)
        done = self.steps >= 5
        return np.array([self.target], np.float32), -miss, False, done, {"is_success": miss < 0.2} if done else {}


class ToyFamily(TaskFamily):
    name = "toy"

    def owns(self, env_id: str) -> bool:
        return env_id == "Toy-v0"

    def env_ids(self) -> tuple[str, ...]:
        return ("Toy-v0",)

    def make_env(
        self, env_id: str, max_steps: int, render_mode: str | None = None, options: Mapping[str, Any] | None = None
    ) -> gym.Env[np.ndarray, Any]:
        return ToyEnv()

    def task_space(self, env_id: str, levels: int) -> TaskSpace:
        return TaskSpace([Parameter("target", -1.0, 1.0, hardest=1.0, easiest=0.0)])

    def policy_shape(self, env_id: str) -> PolicyShape:
        return PolicyShape(observation_dim=1, action_dim=1)
'''


def add_toy_family(tree: Path) -> None:
    (tree / TOY_MODULE).write_text(TOY_SOURCE)
    registry = tree / REGISTRY
    text = registry.read_text()
    anchor = "from common.families.minigrid import MiniGridFamily\n"
    assert text.count(anchor) == 1 and text.count("    MiniGridFamily(),\n") == 1
    text = text.replace(anchor, anchor + "from common.families.toy import ToyFamily\n")
    text = text.replace("    MiniGridFamily(),\n", "    MiniGridFamily(),\n    ToyFamily(),\n")
    registry.write_text(text)


@pytest.fixture(scope="module")
def trees(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    before, after = tmp_path_factory.mktemp("before"), tmp_path_factory.mktemp("after")
    return copies_before_and_after(before, after, PACKAGES, add_toy_family)


def test_a_new_family_is_its_module_and_the_registry(trees: tuple[Path, Path]) -> None:
    before, after = trees
    assert changed_files(before, after) == sorted([str(REGISTRY), str(TOY_MODULE)])
    added = [line for line in (after / REGISTRY).read_text().splitlines() if "Toy" in line]
    assert added == ["from common.families.toy import ToyFamily", "    ToyFamily(),"]


def test_the_copy_trains_and_evaluates_on_the_new_family(trees: tuple[Path, Path], tmp_path: Path) -> None:
    _, after = trees
    env = {**os.environ, "PYTHONPATH": str(after), "PYTHONSAFEPATH": "1"}
    command = [sys.executable, "-c", "import sys, kuka_curriculum; sys.exit(kuka_curriculum.main(sys.argv[1:]))"]

    def kuka_curriculum(*args: str) -> subprocess.CompletedProcess[str]:
        """The copy's command, run beside the run directory with only the copy's packages on the path."""
        done = subprocess.run([*command, *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-3000:]
        return done

    run_dir = str(tmp_path / "toy-run")
    flags = ["--workers", "1", "--envs-per-worker", "2", "--rollout-length", "64", "--eval-every", "1"]
    trained = kuka_curriculum(
        "train", "--env", "Toy-v0", "--teacher", "random", "--total-steps", "256", "--run-dir", run_dir, *flags
    )
    assert "final checkpoint:" in trained.stdout
    evaluated = kuka_curriculum("evaluate", run_dir, "--episodes", "4", "--processes", "1")
    assert "Toy-v0, hardest task, 4 episodes" in evaluated.stdout
