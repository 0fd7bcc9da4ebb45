"""Every teacher kind on the ALP-GMM paper's toy, over HTTP against a real ``serve``.

The toy is teachDeepRL's ``toy_env.py`` (Portelas et al. 2019):

- Tasks live in [0, 1]^D; only the first two dimensions matter, cut into a 10 x 10 grid of cubes
  (D = 2, and D = 6 with four irrelevant dimensions).
- Practising a cube raises its competence by 1, up to 100, if it is the corner cube (0, 0) or a
  lower neighbour (each index the same or one less, not both the same) has competence >= 75.
- The reward is the cube's competence after the episode, divided by 100.
- The score is the percentage of cubes with competence > 75, read after 5,000, 10,000 and 20,000
  episodes (those within ``--episodes``).

Each (space, teacher, seed) is one curriculum on one ``kuka-curriculum serve`` process: the space
names x0..x{D-1} over [0, 1] (easiest 0, hardest 1), the seed is the run's seed, the parameters are
the kind's defaults. A run draws ``--batch`` tasks (1, as in the reference loop), plays them,
reports the rewards, then waits until no fit is pending, so a fit is in place before the next draw
as in the reference's synchronous loop. Kinds come from ``teacher_service.teachers.TEACHER_KINDS``,
so kinds added later run too; one the service refuses for this space (a 422) is skipped and named.

``--reference DIR`` also runs teachDeepRL's ALP-GMM, Covar-GMM and RIAC (the copies in DIR) in
process on the same toy and seeds, with ``np.random.seed(seed)`` and the constructor's seed. They
import from a throw-away package tree in a temp dir, with a ``gym.spaces.Box`` shim over gymnasium's
whose ``sample`` draws from numpy's global generator like old gym's seeded one did, so a run is
repeatable. RIAC needs ``treelib`` (in the ``dev`` extra).

Usage: PYTHONPATH=. .venv/bin/python bench/teacher_toy.py [--episodes 20000] [--seeds 5]
       [--teachers covar-gmm,riac,random] [--spaces 2,6] [--reference ../shared/reference-teachers]
       [--json toy.json]
"""

from __future__ import annotations

import argparse
import importlib
import itertools
import json
import shutil
import statistics
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from common.schemas import API_PREFIX
from teacher_service.process import ServiceProcess
from teacher_service.teachers import TEACHER_KINDS

CUBES = 10
MAX_COMPETENCE = 100
UNLOCK_AT = 75
"""A lower neighbour at this competence or more unlocks a cube."""
MASTERED_ABOVE = 75
"""A cube with more competence than this counts as mastered."""
RELEVANT_DIMS = 2
CHECKPOINTS = (5_000, 10_000, 20_000)
FIT_POLL_S = 0.02

REFERENCE_CLASSES = {"alp-gmm": ("alp_gmm", "ALPGMM"), "covar-gmm": ("covar_gmm", "CovarGMM"), "riac": ("riac", "RIAC")}
"""Our kind to the reference module and class that implement the same teacher."""

GYM_SHIM = '''"""gym.spaces.Box for the teachDeepRL code: gymnasium's, with bounds copied and samples drawn from
numpy's global generator (seeded by the benchmark), as a seeded old-gym Box drew from its own."""
import numpy as np
from gymnasium import spaces


class Box(spaces.Box):
    def __init__(self, low, high, shape=None, dtype=np.float32):
        super().__init__(np.array(low, copy=True), np.array(high, copy=True), shape, dtype)

    def sample(self, mask=None, probability=None):
        return np.random.uniform(self.low, self.high).astype(self.dtype)
'''


class Toy:
    """Competence per cube of the 10 x 10 grid over the first two task dimensions."""

    def __init__(self) -> None:
        self.competence = np.zeros((CUBES,) * RELEVANT_DIMS, dtype=np.int64)
        self.edges = np.arange(0.0, 1.0 + 1.0 / CUBES, 1.0 / CUBES)

    def cube(self, point: np.ndarray) -> tuple[int, ...]:
        """The cube a point falls in; a value on an inner edge belongs to the upper cube, 1.0 to the last."""
        bins = np.searchsorted(self.edges, point[:RELEVANT_DIMS], side="right") - 1
        return tuple(int(b) for b in np.clip(bins, 0, CUBES - 1))

    def unlocked(self, cube: tuple[int, ...]) -> bool:
        if not any(cube):
            return True
        for lower in itertools.product(*[sorted({index, max(index - 1, 0)}) for index in cube]):
            if lower != cube and self.competence[lower] >= UNLOCK_AT:
                return True
        return False

    def episode(self, point: np.ndarray) -> float:
        if np.any(point < 0.0) or np.any(point > 1.0):
            raise ValueError(f"task {point} is outside [0, 1]")
        cube = self.cube(point)
        if self.unlocked(cube):
            self.competence[cube] = min(self.competence[cube] + 1, MAX_COMPETENCE)
        return float(self.competence[cube]) / MAX_COMPETENCE

    def mastered(self) -> float:
        return 100.0 * float(np.mean(self.competence > MASTERED_ABOVE))


@dataclass(frozen=True)
class Run:
    dims: int
    teacher: str
    implementation: str
    """"ours" (over HTTP) or "reference" (teachDeepRL in process)."""
    seed: int
    mastered: dict[int, float]
    """Percent of cubes mastered after each checkpoint's number of episodes."""
    seconds: float


def toy_space(dims: int) -> list[dict[str, Any]]:
    return [{"name": f"x{i}", "low": 0.0, "high": 1.0, "easiest": 0.0, "hardest": 1.0} for i in range(dims)]


def play(toy: Toy, episodes: int, checkpoints: list[int], step: Callable[[int], int]) -> dict[int, float]:
    """Call ``step(at_most)`` (which plays some episodes and returns how many) until ``episodes``,
    reading the score at each checkpoint."""
    mastered: dict[int, float] = {}
    done = 0
    for checkpoint in checkpoints:
        while done < checkpoint:
            done += step(checkpoint - done)
        mastered[checkpoint] = toy.mastered()
    return mastered


class ServiceRunner:
    """Our teachers, one curriculum per run, through the HTTP API of one service."""

    def __init__(self, url: str, batch: int, bar: tqdm[Any]) -> None:
        self.http = httpx.Client(base_url=f"{url}{API_PREFIX}/curricula", timeout=60.0)
        self.batch = batch
        self.bar = bar

    def register(self, name: str, kind: str, dims: int, seed: int) -> str | None:
        """Create the curriculum; the service's reason when it refuses this kind on this space."""
        body = {"teacher": kind, "space": toy_space(dims), "seed": seed, "params": {}}
        response = self.http.put(f"/{name}", json=body)
        if response.status_code == 422:
            return json.dumps(response.json()["detail"])[:300]
        response.raise_for_status()
        return None

    def run(self, name: str, dims: int, episodes: int, checkpoints: list[int]) -> dict[int, float]:
        toy = Toy()
        names = [f"x{i}" for i in range(dims)]

        def step(at_most: int) -> int:
            drawn = self.http.post(f"/{name}/tasks", json={"count": min(self.batch, at_most)})
            drawn.raise_for_status()
            results = []
            for issued in drawn.json()["tasks"]:
                point = np.array([issued["params"][n] for n in names])
                results.append({"task_id": issued["task_id"], "reward": toy.episode(point)})
            self.http.post(f"/{name}/results", json={"results": results}).raise_for_status()
            self.wait_for_fits(name)
            self.bar.update(len(results))
            return len(results)

        return play(toy, episodes, checkpoints, step)

    def wait_for_fits(self, name: str) -> None:
        while True:
            response = self.http.get(f"/{name}")
            response.raise_for_status()
            if response.json()["counters"]["fits_pending"] == 0:
                return
            time.sleep(FIT_POLL_S)


@contextmanager
def reference_modules(directory: Path) -> Iterator[dict[str, Any]]:
    """The teachDeepRL classes, imported from a package tree built in a temp dir."""
    with tempfile.TemporaryDirectory(prefix="teachdrl-") as temp:
        root = Path(temp)
        algos, utils, gym = root / "teachDRL/teachers/algos", root / "teachDRL/teachers/utils", root / "gym"
        for package in (root / "teachDRL", root / "teachDRL/teachers", algos, utils, gym):
            package.mkdir(parents=True, exist_ok=True)
            (package / "__init__.py").touch()
        for module, _ in REFERENCE_CLASSES.values():
            shutil.copy(directory / f"{module}.py", algos / f"{module}.py")
        shutil.copy(directory / "dataset.py", utils / "dataset.py")
        (gym / "spaces.py").write_text(GYM_SHIM)
        sys.path.insert(0, temp)
        try:
            yield {
                kind: getattr(importlib.import_module(f"teachDRL.teachers.algos.{module}"), name)
                for kind, (module, name) in REFERENCE_CLASSES.items()
            }
        finally:
            sys.path.remove(temp)


def run_reference(
    teacher_class: Any, dims: int, seed: int, episodes: int, checkpoints: list[int], bar: tqdm[Any]
) -> dict[int, float]:
    np.random.seed(seed)
    teacher = teacher_class([0.0] * dims, [1.0] * dims, seed=seed)
    toy = Toy()

    def step(at_most: int) -> int:
        task = np.asarray(teacher.sample_task())
        teacher.update(np.array(task), toy.episode(task.astype(np.float64)))
        bar.update(1)
        return 1

    return play(toy, episodes, checkpoints, step)


def describe(run: Run) -> str:
    """One finished run, as a progress line."""
    scores = ", ".join(f"{episodes:,}: {score:.0f}%" for episodes, score in run.mastered.items())
    return f"{run.dims}-D {run.teacher} ({run.implementation}) seed {run.seed}: {scores} in {run.seconds:.0f} s"


def summarise(runs: list[Run], checkpoints: list[int], skipped: dict[str, str]) -> str:
    lines = [
        f"% of the 100 cubes mastered (competence > {MASTERED_ABOVE}) after "
        + ", ".join(f"{c:,}" for c in checkpoints)
        + " episodes: mean over seeds, then the last checkpoint per seed",
        f"{'space':<6} {'teacher':<24} " + " ".join(f"{c:>7,}" for c in checkpoints) + "  per seed (last)",
    ]
    groups: dict[tuple[int, str, str], list[Run]] = {}
    for run in runs:
        groups.setdefault((run.dims, run.teacher, run.implementation), []).append(run)
    finals: dict[tuple[int, str, str], float] = {}
    for (dims, teacher, implementation), members in sorted(groups.items()):
        label = teacher if implementation == "ours" else f"{teacher} (reference)"
        means = [statistics.fmean(run.mastered[c] for run in members) for c in checkpoints]
        finals[(dims, teacher, implementation)] = means[-1]
        per_seed = " ".join(f"{run.mastered[checkpoints[-1]]:.0f}" for run in sorted(members, key=lambda r: r.seed))
        lines.append(f"{dims}-D    {label:<24} " + " ".join(f"{m:7.1f}" for m in means) + f"  [{per_seed}]")
    for (dims, teacher, implementation), final in sorted(finals.items()):
        reference = finals.get((dims, teacher, "reference"))
        if implementation == "ours" and reference is not None:
            ratio = f"{final / reference:.2f}x" if reference > 0 else "n/a (reference 0)"
            lines.append(f"{dims}-D    {teacher}: ours / reference at {checkpoints[-1]:,} episodes = {ratio}")
    lines += [f"skipped {what}: {why}" for what, why in skipped.items()]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=CHECKPOINTS[-1], help="episodes per run")
    parser.add_argument("--seeds", type=int, default=5, help="runs per teacher and space; seeds 1..N")
    parser.add_argument("--teachers", default="", help="comma-separated kinds (default: every registered kind)")
    parser.add_argument("--spaces", default="2,6", help="comma-separated task-space dimensions (2 and/or 6)")
    parser.add_argument("--batch", type=int, default=1, help="tasks drawn per request")
    parser.add_argument("--reference", type=Path, help="teachDeepRL teachers to run beside ours")
    parser.add_argument("--json", type=Path, default=Path("teacher_toy.json"), help="where to write every run")
    args = parser.parse_args()
    # One BLAS thread for the reference's in-process fits, as our fit process has: on a shared
    # machine more threads only contend.
    threadpool_limits(limits=1)
    # Duplicate-heavy early fits make scikit-learn warn; the warnings say nothing about the result.
    warnings.filterwarnings("ignore", category=ConvergenceWarning)
    # The reference builds float32 boxes from float64 bounds; gymnasium warns about each one.
    warnings.filterwarnings("ignore", message=".*precision lowered by casting to float32")

    kinds = [k for k in args.teachers.split(",") if k] or sorted(TEACHER_KINDS)
    unknown = sorted(set(kinds) - set(TEACHER_KINDS))
    if unknown:
        parser.error(f"unknown teacher kinds {unknown}; registered: {sorted(TEACHER_KINDS)}")
    spaces = [int(d) for d in args.spaces.split(",")]
    if any(d < RELEVANT_DIMS for d in spaces):
        parser.error(f"every space needs at least {RELEVANT_DIMS} dimensions")
    checkpoints = sorted({c for c in CHECKPOINTS if c < args.episodes} | {args.episodes})
    seeds = range(1, args.seeds + 1)
    references = [k for k in kinds if k in REFERENCE_CLASSES] if args.reference else []
    total = args.episodes * len(seeds) * len(spaces) * (len(kinds) + len(references))

    runs: list[Run] = []
    skipped: dict[str, str] = {}
    with (
        tempfile.TemporaryDirectory(prefix="teacher-toy-") as temp,
        ServiceProcess(Path(temp) / "toy.db") as service,
        tqdm(total=total, desc="toy episodes", unit="ep", smoothing=0.05) as bar,
    ):
        runner = ServiceRunner(service.url, args.batch, bar)
        for dims, kind, seed in itertools.product(spaces, kinds, seeds):
            name = f"toy-{dims}d-{kind}-{seed}"
            reason = runner.register(name, kind, dims, seed)
            if reason is not None:
                skipped[f"{kind} on {dims}-D"] = reason
                bar.update(args.episodes)
                continue
            start = time.perf_counter()
            mastered = runner.run(name, dims, args.episodes, checkpoints)
            runs.append(Run(dims, kind, "ours", seed, mastered, time.perf_counter() - start))
            bar.write(describe(runs[-1]))
        if references:
            with reference_modules(args.reference) as classes:
                for dims, kind, seed in itertools.product(spaces, references, seeds):
                    start = time.perf_counter()
                    mastered = run_reference(classes[kind], dims, seed, args.episodes, checkpoints, bar)
                    runs.append(Run(dims, kind, "reference", seed, mastered, time.perf_counter() - start))
                    bar.write(describe(runs[-1]))

    print(summarise(runs, checkpoints, skipped))
    args.json.write_text(
        json.dumps(
            {
                "command": " ".join(sys.argv),
                "episodes": args.episodes,
                "seeds": list(seeds),
                "checkpoints": checkpoints,
                "runs": [asdict(run) for run in runs],
                "skipped": skipped,
            },
            indent=1,
        )
    )
    print(f"every run: {args.json}")


if __name__ == "__main__":
    main()
