"""How fast one core runs the KUKA grasp environment, against the original it reimplements.

Random actions, counting resets and the scripted grasps that end episodes, as a rollout worker would see
it, for each variant:
- ``original``: ``pybullet_envs.bullet.kukaGymEnv.KukaGymEnv`` from the pybullet wheel (the book's
  environment), behind a minimal gymnasium shim; it reloads every model at each reset;
- ``v0``: ``KukaGrasp-v0`` at its hardest task (the book's evaluation setting);
- ``v0-reload``: the same, rebuilding the scene from the model files at every reset, as the original;
- ``hard-v1``: ``KukaGraspHard-v1`` at its hardest point, where training is timed (``bench/train_speed.py``).

Each measurement runs in a fresh process (the original keeps pybullet's global client), one at a time,
and the variants take turns over ``--rounds`` rounds, so a machine whose load changes slows them alike.
Times are CPU seconds of the measuring process (wall-clock rates are printed too).

    .venv/bin/python bench/env_speed.py --steps 20000 --seed 0 --rounds 2
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import os
import random
import subprocess
import sys
import tempfile
import time
import types
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

# A sibling script (bench/ is the script's path, not a package).
from episode_equivalence import export_commit

from common.kuka import ENV_ID, HARD_V1_ENV_ID
from common.kuka.bullet import native_output_silenced
from common.kuka.env import make_kuka_env

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = ("original", "v0", "v0-reload", "hard-v1")


@dataclass
class SpeedReport:
    steps: int = 0
    resets: int = 0
    finished: int = 0
    successes: int = 0
    grasps: int = 0
    total_s: float = 0.0
    wall_s: float = 0.0
    reset_s: float = 0.0
    step_s: float = 0.0
    grasp_s: float = 0.0
    rates: list[float] = field(default_factory=list)
    """Steps per CPU second of each round."""

    def add(self, other: SpeedReport) -> None:
        for name in ("steps", "resets", "finished", "successes", "grasps"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        for name in ("total_s", "wall_s", "reset_s", "step_s", "grasp_s"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        self.rates.append(other.steps / other.total_s)

    @property
    def rate(self) -> float:
        return self.steps / self.total_s

    def lines(self, label: str) -> list[str]:
        plain_s = self.step_s - self.grasp_s
        rounds = ", ".join(f"{rate:.0f}" for rate in self.rates)
        return [
            f"{label}:",
            f"  env steps/s per core : {self.rate:8.0f}  (resets and grasps included; rounds {rounds};"
            f" {self.steps / self.wall_s:.0f} by the wall clock)",
            f"  mean reset           : {1e3 * self.reset_s / self.resets:8.2f} ms over {self.resets} resets",
            f"  mean plain step      : {1e6 * plain_s / max(self.steps - self.grasps, 1):8.1f} us"
            " (steps that did not grasp)",
            f"  mean grasping step   : {1e3 * self.grasp_s / max(self.grasps, 1):8.2f} ms over {self.grasps} grasps",
            f"  successes            : {self.successes}/{self.finished} finished episodes",
        ]


class OriginalKukaEnv(gymnasium.Env[np.ndarray, np.ndarray]):
    """The wheel's ``KukaGymEnv`` behind gymnasium's reset and step signatures.

    It imports the retired ``gym`` package and ``pkg_resources``; the few names it uses are supplied from
    gymnasium and ``packaging``. It places the block with Python's global ``random``, seeded at reset.
    """

    def __init__(self) -> None:
        from gymnasium.utils import seeding
        from packaging.version import parse

        gym = types.ModuleType("gym")
        gym.Env = gymnasium.Env  # type: ignore[attr-defined]
        gym.spaces = gymnasium.spaces  # type: ignore[attr-defined]
        gym.__version__ = "0.26.2"
        utils = types.ModuleType("gym.utils")
        utils.seeding = seeding  # type: ignore[attr-defined]
        gym.utils = utils  # type: ignore[attr-defined]
        pkg_resources = types.ModuleType("pkg_resources")
        pkg_resources.parse_version = parse  # type: ignore[attr-defined]
        sys.modules.update({"gym": gym, "gym.spaces": gymnasium.spaces, "gym.utils": utils})
        sys.modules.update({"gym.utils.seeding": seeding, "pkg_resources": pkg_resources})
        # The package's __init__ registers every environment with gym; only the two KUKA modules are needed.
        spec = importlib.util.find_spec("pybullet_envs")
        if spec is None or not spec.submodule_search_locations:
            raise RuntimeError("pybullet_envs is not installed with pybullet")
        root = list(spec.submodule_search_locations)[0]
        for name, path in (("pybullet_envs", root), ("pybullet_envs.bullet", os.path.join(root, "bullet"))):
            package = types.ModuleType(name)
            package.__path__ = [path]
            sys.modules[name] = package
        with native_output_silenced():
            module = importlib.import_module("pybullet_envs.bullet.kukaGymEnv")
            self._env = module.KukaGymEnv(renders=False, isDiscrete=False, maxSteps=1000)
        self.action_space = self._env.action_space
        self.observation_space = self._env.observation_space

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if seed is not None:
            random.seed(seed)
        return self._env.reset(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        observation, reward, done, _ = self._env.step(action)
        # The original ends an episode by its step limit as by a grasp; only a grasp lifts the block.
        return observation, reward, bool(done), False, {"is_success": reward > 5000}


def make_variant(variant: str) -> gymnasium.Env[np.ndarray, np.ndarray]:
    if variant == "original":
        return OriginalKukaEnv()
    if variant == "hard-v1":
        return make_kuka_env(HARD_V1_ENV_ID)
    return make_kuka_env(ENV_ID, reload_on_reset=variant == "v0-reload")


def measure(variant: str, steps: int, seed: int) -> SpeedReport:
    """``steps`` random-action steps of a fresh ``variant``, in this process."""
    env = make_variant(variant)
    actions = np.random.default_rng(seed).uniform(-1.0, 1.0, size=(steps, 3)).astype(np.float32)
    report = SpeedReport(steps=steps)
    needs_reset = True
    start, wall_start = time.process_time(), time.perf_counter()
    for action in actions:
        if needs_reset:
            tick = time.process_time()
            env.reset(seed=seed + report.resets)
            report.reset_s += time.process_time() - tick
            report.resets += 1
        tick = time.process_time()
        _, _, terminated, truncated, info = env.step(action)
        elapsed = time.process_time() - tick
        report.step_s += elapsed
        if terminated:
            report.grasps += 1
            report.grasp_s += elapsed
        needs_reset = bool(terminated or truncated)
        report.finished += needs_reset
        report.successes += bool(info["is_success"])
    report.total_s, report.wall_s = time.process_time() - start, time.perf_counter() - wall_start
    env.close()
    return report


def measure_in_subprocess(variant: str, steps: int, seed: int, common_root: Path | None, scratch: Path) -> SpeedReport:
    """``measure`` in a fresh process (the original keeps pybullet's global client), importing ``common`` from
    ``common_root`` (an exported baseline) when given, else from the working tree."""
    environment = dict(os.environ)
    if common_root is not None:
        environment["PYTHONPATH"] = os.pathsep.join(filter(None, [str(common_root), environment.get("PYTHONPATH")]))
    out = scratch / "report.json"
    command = [sys.executable, __file__, "--measure", variant, str(out), "--steps", str(steps), "--seed", str(seed)]
    subprocess.run(command, cwd=ROOT, env=environment, check=True)
    return SpeedReport(**json.loads(out.read_text()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000, help="env steps per variant and round")
    parser.add_argument("--seed", type=int, default=0, help="seed of the actions and block placements")
    parser.add_argument("--rounds", type=int, default=2, help="turns each variant takes (default 2)")
    parser.add_argument("--variants", nargs="+", choices=VARIANTS, default=list(VARIANTS))
    parser.add_argument(
        "--baseline", metavar="COMMIT", help="also measure this commit's environment for each variant but the original"
    )
    parser.add_argument("--measure", nargs=2, metavar=("VARIANT", "OUT"), help=argparse.SUPPRESS)  # one measurement
    args = parser.parse_args()
    if args.steps < 1 or args.rounds < 1:
        parser.error("--steps and --rounds must be at least 1")
    if args.measure is not None:
        variant, out = args.measure
        Path(out).write_text(json.dumps(asdict(measure(variant, args.steps, args.seed))))
        return

    with tempfile.TemporaryDirectory() as directory:
        scratch = Path(directory)
        sides: list[tuple[str, str, Path | None]] = [(variant, variant, None) for variant in args.variants]
        if args.baseline is not None:
            exported = export_commit(args.baseline, scratch / "baseline", "common")
            others = [variant for variant in args.variants if variant != "original"]
            sides += [(f"{variant} at {args.baseline}", variant, exported) for variant in others]
        reports = {label: SpeedReport() for label, _, _ in sides}
        load = os.getloadavg()[0]
        for round_index in range(args.rounds):
            for label, variant, common_root in sides:
                seed = args.seed + round_index * 100_000
                reports[label].add(measure_in_subprocess(variant, args.steps, seed, common_root, scratch))
    print(f"load average (1 min) {load:.2f} before the runs, {os.getloadavg()[0]:.2f} after")
    for label, report in reports.items():
        print("\n".join(report.lines(label)))
    ours = [variant for variant in args.variants if variant != "original"]
    if "original" in reports:
        original = reports["original"].rate
        print(
            "against the original (CPU-time rates): "
            + ", ".join(f"{v} {reports[v].rate / original:.2f}x" for v in ours)
        )
    if args.baseline is not None:
        ratios = [f"{v} {reports[v].rate / reports[f'{v} at {args.baseline}'].rate:.2f}x" for v in ours]
        print(f"against {args.baseline} (CPU-time rates): " + ", ".join(ratios))


if __name__ == "__main__":
    main()
