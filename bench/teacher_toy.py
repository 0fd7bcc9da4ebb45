"""Every teacher kind on the ALP-GMM paper's toy, over HTTP against a real ``serve``; resumable.

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
the kind's defaults overridden by ``--teacher-param KIND.NAME=VALUE`` (repeatable; VALUE is read as
JSON, else taken as a string; checked against the kind's parameter model before anything runs). A
run draws ``--batch`` tasks (1, as in the reference loop), plays them, reports the rewards, then
waits until no fit is pending, so a fit is in place before the next draw as in the reference's
synchronous loop. Kinds come from ``teacher_service.teachers.TEACHER_KINDS``, so kinds added later
run too; one the service refuses for this space (a 422) is recorded as refused, with the reason.

``--reference DIR`` also runs teachDeepRL's ALP-GMM, Covar-GMM and RIAC (the copies in DIR) in
process on the same toy and seeds, with ``np.random.seed(seed)``, the constructor's seed and the
reference's default parameters. They import from a throw-away package tree in a temp dir, with a
``gym.spaces.Box`` shim over gymnasium's whose ``sample`` draws from numpy's global generator like
old gym's seeded one did, so a run is repeatable. RIAC needs ``treelib`` (in the ``dev`` extra).

With ``DIR/currot`` present (psclklnk/currot's main branch, see its README), ``--reference`` also runs
the authors' CURROT, through their TeachMyAgent adapter (``TMAContinuousBarycenterCurriculum``:
uniform starting particles and target), and their SPDL (``SelfPacedTeacherV2``, fed the returns of
every ``update_every`` episodes). Their settings are ours translated (``reference_settings``): from
``currot``'s effective parameters (defaults plus ``--teacher-param``) the particles, the update
interval, the move radius (``max_move`` of the unit box's diagonal; the authors take the square root
of their ``epsilon``, so it gets the radius squared) and the return bar (ours' ``delta``, else 0.5,
the middle of the toy's rewards, which is the adapter's own default for rewards in [0, 1]); from
``self-paced``'s the start, the spreads, the target (``uniform``: N(0.5, I/12)), the bar (``zeta``,
on the toy's [0, 1] returns), the KL limit and the update interval. Each such run records those
settings as its parameters, and ours is compared with the reference run of matching settings. The
adapter only starts and aims uniform, so ``currot`` with another ``start`` or ``target`` has no
reference run. ``np.random.seed(seed)`` and ``torch.manual_seed(seed)`` make them repeatable.

A full run takes hours, so the driver resumes: each finished run (ours or the reference's, refused
ones too) is appended at once to ``--out`` as one JSON line and fsync'd, so a kill loses at most the
run in progress. On start the driver reads that file and skips every run already in it; a run is
the same run when its space, teacher, implementation, seed, parameters, batch and episodes all
match, so changing a parameter runs anew beside the old lines. The summary table (and ``--json``)
covers every line in the file, not only this invocation's. One file holds one ``--episodes``; an
unfinished last line (a kill mid-write) is dropped.

``--in-process`` plays our kinds in the driver's process instead (``make_teacher``, then
``sample(1)`` and ``learn_and_fit`` per episode): the same calls in the same order as the service
makes with ``--batch 1``, which installs each due fit before the next draw, so the same tasks and
scores at a fraction of the cost (HTTP, the store and the fit process), for a busy machine. Its
runs are recorded as such (``"in_process": true``) and count as ours in the comparison.

``--jobs N`` plays N runs at once in N processes, each with its own service; the driver alone writes
the results file. A run's score does not depend on it (each run is its own seeded curriculum and
toy); its recorded seconds then include the other jobs' contention.

Usage: PYTHONPATH=. .venv/bin/python bench/teacher_toy.py [--episodes 20000] [--seeds 5]
       [--teachers covar-gmm,riac,random] [--spaces 2,6] [--batch 1] [--jobs 1]
       [--teacher-param self-paced.target=uniform] [--reference ../shared/reference-teachers]
       [--out teacher_toy.jsonl] [--json toy.json]
"""

from __future__ import annotations

import argparse
import fcntl
import importlib
import itertools
import json
import math
import multiprocessing
import os
import queue
import shutil
import signal
import statistics
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager, redirect_stdout
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from types import FrameType
from typing import Any, Protocol

import httpx
import numpy as np
import scipy.stats
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from common.client.schemas import API_PREFIX
from common.client.task_space import Parameter, TaskSpace
from teacher_service.process import ServiceProcess
from teacher_service.teachers import TEACHER_KINDS, EpisodeResult, make_teacher
from teacher_service.teachers.currot import CurrotParams
from teacher_service.teachers.self_paced import SelfPacedParams

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

AUTHORS_DIR = "currot"
"""The authors' CURROT and SPDL, inside the ``--reference`` directory."""
AUTHORS_CLASSES = {
    "currot": ("deep_sprl.teachers.spl.currot_tma", "TMAContinuousBarycenterCurriculum"),
    "self-paced": ("deep_sprl.teachers.spl.self_paced_teacher_v2", "SelfPacedTeacherV2"),
}
"""Our kind to the authors' module and class (psclklnk/currot, main branch)."""
TOY_REWARD_RANGE = (0.0, 1.0)
"""The toy's rewards, as the authors' adapter is told them."""

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
class RunId:
    """What makes two runs the same run: the driver skips every id already in its results file."""

    dims: int
    teacher: str
    implementation: str
    """"ours" (over HTTP) or "reference" (teachDeepRL in process)."""
    seed: int
    params: str
    """The kind's parameters given on the command line (not its defaults), as canonical JSON."""
    batch: int
    """Tasks drawn per request; the reference draws one per update."""
    episodes: int
    in_process: bool = False
    """Ours played in the driver's process (``--in-process``) rather than over HTTP."""


@dataclass(frozen=True)
class Run:
    """One finished run: one line of the results file."""

    id: RunId
    mastered: dict[int, float] | None
    """Percent of cubes mastered after each checkpoint's number of episodes; None when refused."""
    refused: str | None
    """The service's reason for refusing this kind on this space."""
    seconds: float
    finished: str
    """UTC time the run ended, ISO 8601."""

    def record(self) -> dict[str, Any]:
        """The JSON line: the id's fields flat, parameters as an object, checkpoints as string keys."""
        mastered = None if self.mastered is None else {str(c): m for c, m in self.mastered.items()}
        return {
            "dims": self.id.dims,
            "teacher": self.id.teacher,
            "implementation": self.id.implementation,
            "seed": self.id.seed,
            "params": json.loads(self.id.params),
            "batch": self.id.batch,
            "episodes": self.id.episodes,
            **({"in_process": True} if self.id.in_process else {}),
            "mastered": mastered,
            "refused": self.refused,
            "seconds": round(self.seconds, 1),
            "finished": self.finished,
        }

    @classmethod
    def from_record(cls, record: dict[str, Any]) -> Run:
        mastered = record["mastered"]
        return cls(
            RunId(
                int(record["dims"]),
                str(record["teacher"]),
                str(record["implementation"]),
                int(record["seed"]),
                canonical(record["params"]),
                int(record["batch"]),
                int(record["episodes"]),
                bool(record.get("in_process", False)),
            ),
            None if mastered is None else {int(c): float(m) for c, m in mastered.items()},
            record["refused"],
            float(record["seconds"]),
            str(record["finished"]),
        )


def canonical(params: dict[str, Any]) -> str:
    return json.dumps(params, sort_keys=True, separators=(",", ":"))


def now_utc() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def load_runs(path: Path) -> list[Run]:
    """The runs in the results file, first of each id kept; an unfinished last line is cut off."""
    if not path.exists():
        return []
    data = path.read_bytes()
    complete = data.rfind(b"\n") + 1
    if complete < len(data):
        print(f"{path}: dropping an unfinished last line ({len(data) - complete} bytes)", file=sys.stderr)
        with path.open("r+b") as results:
            results.truncate(complete)
            os.fsync(results.fileno())
    runs: dict[RunId, Run] = {}
    for number, line in enumerate(data[:complete].decode().splitlines(), start=1):
        if not line.strip():
            continue
        try:
            run = Run.from_record(json.loads(line))
        except (ValueError, KeyError, TypeError, AttributeError) as error:
            raise SystemExit(f"{path}:{number}: not a run record ({error!r}); fix or move the file") from None
        runs.setdefault(run.id, run)
    return list(runs.values())


def append_run(path: Path, run: Run) -> None:
    """One line, flushed to disk before the next run starts."""
    with path.open("a") as results:
        results.write(json.dumps(run.record()) + "\n")
        results.flush()
        os.fsync(results.fileno())


def toy_space(dims: int) -> list[dict[str, Any]]:
    return [{"name": f"x{i}", "low": 0.0, "high": 1.0, "easiest": 0.0, "hardest": 1.0} for i in range(dims)]


class Progress(Protocol):
    """Where finished episodes are counted: the progress bar, or a job's message queue."""

    def update(self, n: int) -> object: ...


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

    def __init__(self, url: str, batch: int, bar: Progress) -> None:
        self.http = httpx.Client(base_url=f"{url}{API_PREFIX}/curricula", timeout=60.0)
        self.batch = batch
        self.bar = bar

    def register(self, name: str, kind: str, dims: int, seed: int, params: dict[str, Any]) -> str | None:
        """Create the curriculum; the service's reason when it refuses this kind on this space."""
        body = {"teacher": kind, "space": toy_space(dims), "seed": seed, "params": params}
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


def run_in_process(
    kind: str, dims: int, seed: int, params: dict[str, Any], checkpoints: list[int], bar: Progress
) -> dict[int, float] | str:
    """One of our kinds on the toy without the service (see ``--in-process``); the reason when the
    kind refuses this space or these parameters."""
    space = TaskSpace([Parameter(**parameter) for parameter in toy_space(dims)])
    try:
        teacher = make_teacher(kind, space, seed, params)
    except ValueError as error:
        return str(error)[:300]
    toy = Toy()
    names = [f"x{i}" for i in range(dims)]

    def step(at_most: int) -> int:
        task = teacher.sample(1)[0]
        teacher.learn_and_fit(EpisodeResult(task, toy.episode(np.array([task[name] for name in names]))))
        bar.update(1)
        return 1

    return play(toy, checkpoints[-1], checkpoints, step)


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
        authors = directory / AUTHORS_DIR
        if authors.is_dir():
            for package in ("deep_sprl", "TeachMyAgent"):
                shutil.copytree(authors / package, root / package)
        sys.path.insert(0, temp)
        try:
            classes = {
                kind: getattr(importlib.import_module(f"teachDRL.teachers.algos.{module}"), name)
                for kind, (module, name) in REFERENCE_CLASSES.items()
            }
            if authors.is_dir():
                classes.update(
                    {
                        kind: getattr(importlib.import_module(module), name)
                        for kind, (module, name) in AUTHORS_CLASSES.items()
                    }
                )
            yield classes
        finally:
            sys.path.remove(temp)


def reference_settings(kind: str, dims: int, params: dict[str, Any]) -> dict[str, Any] | None:
    """The settings of the reference run that ``kind`` with ``params`` (ours) is compared with, as
    recorded in that run's parameters; ``None`` when no reference can run them (see the module
    docstring). teachDeepRL's run with their defaults: ``{}``."""
    if kind in REFERENCE_CLASSES:
        return {}
    if kind not in AUTHORS_CLASSES or kind not in TEACHER_KINDS:
        return None
    if kind == "currot":
        ours = CurrotParams.parse(params)
        if ours.start != "uniform" or ours.target != "uniform":
            return None
        delta = ours.delta
        return {
            "particles": ours.particles,
            "update_every": ours.update_every,
            "max_move": ours.max_move,
            "delta": float(statistics.fmean(TOY_REWARD_RANGE) if delta is None else delta),
        }
    spdl = SelfPacedParams.parse(params)
    start = spdl.start
    return {
        "start": [0.0] * dims if start is None else [float(start[f"x{i}"]) for i in range(dims)],
        "initial_spread": spdl.initial_spread,
        "target": spdl.target,
        "target_spread": spdl.target_spread,
        "bar": spdl.zeta,
        "kl_limit": spdl.kl_limit,
        "update_every": spdl.update_every,
    }


def run_reference(
    kind: str,
    teacher_class: Any,
    dims: int,
    seed: int,
    settings: dict[str, Any],
    checkpoints: list[int],
    bar: Progress,
) -> dict[int, float]:
    """One reference run on the toy: teachDeepRL's with their defaults, the authors' with ``settings``."""
    np.random.seed(seed)
    toy = Toy()
    if kind == "currot":
        return play_authors_currot(teacher_class, toy, dims, seed, settings, checkpoints, bar)
    if kind == "self-paced":
        return play_authors_spdl(teacher_class, toy, dims, seed, settings, checkpoints, bar)
    teacher = teacher_class([0.0] * dims, [1.0] * dims, seed=seed)

    def step(at_most: int) -> int:
        task = np.asarray(teacher.sample_task())
        teacher.update(np.array(task), toy.episode(task.astype(np.float64)))
        bar.update(1)
        return 1

    return play(toy, checkpoints[-1], checkpoints, step)


def play_authors_currot(
    adapter: Any, toy: Toy, dims: int, seed: int, settings: dict[str, Any], checkpoints: list[int], bar: Progress
) -> dict[int, float]:
    """The authors' CURROT through their TeachMyAgent adapter; it prints every update, so stdout is muted."""
    radius = settings["max_move"] * math.sqrt(dims)
    teacher = adapter(
        [0.0] * dims,
        [1.0] * dims,
        *TOY_REWARD_RANGE,
        perf_lb=settings["delta"],
        n_samples=settings["particles"],
        episodes_per_update=settings["update_every"],
        epsilon=radius**2,
        seed=seed,
    )

    def step(at_most: int) -> int:
        task = np.asarray(teacher.sample_task(), dtype=np.float64)
        teacher.episodic_update(task, toy.episode(task), None)
        bar.update(1)
        return 1

    with open(os.devnull, "w") as muted, redirect_stdout(muted):
        return play(toy, checkpoints[-1], checkpoints, step)


def play_authors_spdl(
    spdl: Any, toy: Toy, dims: int, seed: int, settings: dict[str, Any], checkpoints: list[int], bar: Progress
) -> dict[int, float]:
    """The authors' SPDL, updated with the tasks and returns of every ``update_every`` episodes (their
    ``SelfPacedWrapper``'s loop, with returns for values as the toy has no critic); muted as above."""
    import torch  # only here: the authors' SPDL is the one part of the benchmark that needs it

    torch.manual_seed(seed)
    torch.set_num_threads(1)  # one thread, as for every fit here; its update is still seconds to a minute
    if settings["target"] == "uniform":
        target_mean, target_cov = np.full(dims, 0.5), np.eye(dims) / 12.0
    else:
        target_mean, target_cov = np.ones(dims), settings["target_spread"] ** 2 * np.eye(dims)
    target = scipy.stats.multivariate_normal(target_mean, target_cov)
    teacher = spdl(
        lambda points: np.atleast_1d(target.logpdf(points)),
        lambda count: np.random.multivariate_normal(target_mean, target_cov, size=count),
        np.array(settings["start"], dtype=np.float64),
        settings["initial_spread"] ** 2,
        (np.zeros(dims), np.ones(dims)),
        settings["bar"],
        max_kl=settings["kl_limit"],
    )
    tasks: list[np.ndarray] = []
    returns: list[float] = []

    def step(at_most: int) -> int:
        task = np.asarray(teacher.sample(), dtype=np.float64)
        tasks.append(task)
        returns.append(toy.episode(task))
        if len(tasks) == settings["update_every"]:
            teacher.update_distribution(np.array(tasks), np.array(returns))
            tasks.clear()
            returns.clear()
        bar.update(1)
        return 1

    with open(os.devnull, "w") as muted, redirect_stdout(muted):
        return play(toy, checkpoints[-1], checkpoints, step)


def describe(run: Run) -> str:
    """One finished run, as a progress line."""
    what = f"{run.id.dims}-D {label(run.id)} seed {run.id.seed}"
    if run.mastered is None:
        return f"{what}: refused: {run.refused}"
    scores = ", ".join(f"{episodes:,}: {score:.0f}%" for episodes, score in run.mastered.items())
    return f"{what}: {scores} in {run.seconds:.0f} s"


def label(run_id: RunId) -> str:
    """The teacher, which implementation, and whatever was set beyond its defaults."""
    text = run_id.teacher if run_id.implementation == "ours" else f"{run_id.teacher} (reference)"
    params = json.loads(run_id.params)
    if params:
        text += " " + ",".join(f"{k}={v if isinstance(v, str) else json.dumps(v)}" for k, v in params.items())
    if run_id.batch != 1:
        text += f" batch {run_id.batch}"
    if run_id.in_process:
        text += " (in process)"
    return text


def summarise(runs: list[Run], checkpoints: list[int]) -> str:
    """Mean score per (space, teacher, parameters) over the seeds it has, and ours against the reference."""
    groups: dict[tuple[int, str, str, str, int, bool], list[tuple[int, dict[int, float]]]] = {}
    labels: dict[tuple[int, str, str, str, int, bool], str] = {}
    refused: dict[str, str] = {}
    for run in runs:
        key = (run.id.dims, run.id.teacher, run.id.implementation, run.id.params, run.id.batch, run.id.in_process)
        labels[key] = label(run.id)
        if run.mastered is None:
            refused[f"{label(run.id)} on {run.id.dims}-D"] = str(run.refused)
        else:
            groups.setdefault(key, []).append((run.id.seed, run.mastered))
    width = max([len(text) for text in labels.values()] + [len("teacher")])
    last = checkpoints[-1]
    lines = [
        f"% of the 100 cubes mastered (competence > {MASTERED_ABOVE}) after "
        + ", ".join(f"{c:,}" for c in checkpoints)
        + " episodes: mean over seeds, then the last checkpoint per seed",
        f"{'space':<6} {'teacher':<{width}} " + " ".join(f"{c:>7,}" for c in checkpoints) + "  seed:score (last)",
    ]
    finals: dict[tuple[int, str, str, str, int, bool], float] = {}
    for key, members in sorted(groups.items()):
        means = [statistics.fmean(mastered[c] for _, mastered in members) for c in checkpoints]
        finals[key] = means[-1]
        per_seed = " ".join(f"{seed}:{mastered[last]:.0f}" for seed, mastered in sorted(members))
        lines.append(f"{key[0]}-D    {labels[key]:<{width}} " + " ".join(f"{m:7.1f}" for m in means) + f"  {per_seed}")
    for key, final in sorted(finals.items()):
        dims, teacher, implementation, params, _, _ = key
        settings = reference_settings(teacher, dims, json.loads(params)) if implementation == "ours" else None
        reference = (
            None if settings is None else finals.get((dims, teacher, "reference", canonical(settings), 1, False))
        )
        if reference is not None:
            ratio = f"{final / reference:.2f}x" if reference > 0 else "n/a (reference 0)"
            lines.append(f"{dims}-D    {labels[key]}: ours / reference at {last:,} episodes = {ratio}")
    lines += [f"refused {what}: {why}" for what, why in sorted(refused.items())]
    return "\n".join(lines)


def teacher_params(given: list[str], parser: argparse.ArgumentParser) -> dict[str, dict[str, Any]]:
    """``KIND.NAME=VALUE`` items as parameters per kind, each kind's set checked by its model."""
    params: dict[str, dict[str, Any]] = {}
    for item in given:
        target, equals, raw = item.partition("=")
        kind, dot, name = target.partition(".")
        if not (equals and dot and kind and name):
            parser.error(f"--teacher-param {item!r}: expected KIND.NAME=VALUE")
        if kind not in TEACHER_KINDS:
            parser.error(f"--teacher-param {item!r}: unknown kind; registered: {sorted(TEACHER_KINDS)}")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        params.setdefault(kind, {})[name] = value
    for kind, values in params.items():
        try:
            TEACHER_KINDS[kind].Params.parse(values)
        except ValueError as error:
            parser.error(f"--teacher-param for {kind}: {error}")
    return params


@contextmanager
def sole_writer(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on the results file, so two drivers never run the same runs into it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a") as results:
        try:
            fcntl.flock(results.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise SystemExit(f"another driver is writing {path}") from None
        yield


def stop_on_sigterm(signum: int, frame: FrameType | None) -> None:
    """Unwind on SIGTERM as on Ctrl-C, so the service process stops with the driver."""
    raise KeyboardInterrupt


def execute(
    todo: list[RunId],
    batch: int,
    reference: Path | None,
    checkpoints: list[int],
    bar: Progress,
    finish: Callable[[Run], None],
) -> None:
    """Play each run in ``todo`` (ours on one service, then the reference's) and ``finish`` it."""
    # One BLAS thread for the reference's in-process fits, as our fit process has: on a shared
    # machine more threads only contend.
    threadpool_limits(limits=1)
    # Duplicate-heavy early fits make scikit-learn warn; the warnings say nothing about the result.
    warnings.filterwarnings("ignore", category=ConvergenceWarning)
    # The reference builds float32 boxes from float64 bounds; gymnasium warns about each one.
    warnings.filterwarnings("ignore", message=".*precision lowered by casting to float32")
    episodes = checkpoints[-1]
    for run_id in [run_id for run_id in todo if run_id.in_process]:
        start = time.perf_counter()
        outcome = run_in_process(run_id.teacher, run_id.dims, run_id.seed, json.loads(run_id.params), checkpoints, bar)
        refused = outcome if isinstance(outcome, str) else None
        mastered = None if isinstance(outcome, str) else outcome
        finish(Run(run_id, mastered, refused, time.perf_counter() - start, now_utc()))
    ours = [run_id for run_id in todo if run_id.implementation == "ours" and not run_id.in_process]
    if ours:
        with (
            tempfile.TemporaryDirectory(prefix="teacher-toy-") as temp,
            ServiceProcess(Path(temp) / "toy.db") as service,
        ):
            runner = ServiceRunner(service.url, batch, bar)
            for run_id in ours:
                start = time.perf_counter()
                name = f"toy-{run_id.dims}d-{run_id.teacher}-{run_id.seed}"
                params = json.loads(run_id.params)
                reason = runner.register(name, run_id.teacher, run_id.dims, run_id.seed, params)
                if reason is not None:
                    bar.update(episodes)
                    finish(Run(run_id, None, reason, time.perf_counter() - start, now_utc()))
                    continue
                mastered = runner.run(name, run_id.dims, episodes, checkpoints)
                finish(Run(run_id, mastered, None, time.perf_counter() - start, now_utc()))
    theirs = [run_id for run_id in todo if run_id.implementation == "reference"]
    if theirs and reference is not None:
        with reference_modules(reference) as classes:
            for run_id in theirs:
                start = time.perf_counter()
                if run_id.teacher not in classes:
                    raise SystemExit(f"{reference / AUTHORS_DIR} is missing: the authors' {run_id.teacher} cannot run")
                settings = json.loads(run_id.params)
                mastered = run_reference(
                    run_id.teacher, classes[run_id.teacher], run_id.dims, run_id.seed, settings, checkpoints, bar
                )
                finish(Run(run_id, mastered, None, time.perf_counter() - start, now_utc()))


class QueuedProgress:
    """A job's progress, sent to the driver's bar."""

    def __init__(self, messages: multiprocessing.Queue[tuple[str, Any]]) -> None:
        self.messages = messages

    def update(self, n: int) -> None:
        self.messages.put(("episodes", n))


def play_share(
    share: list[RunId],
    batch: int,
    reference: Path | None,
    checkpoints: list[int],
    messages: multiprocessing.Queue[tuple[str, Any]],
) -> None:
    """One job: play its share of the runs, sending each finished run to the driver, which writes it."""
    signal.signal(signal.SIGTERM, stop_on_sigterm)
    try:
        execute(
            share,
            batch,
            reference,
            checkpoints,
            QueuedProgress(messages),
            lambda run: messages.put(("run", run.record())),
        )
        messages.put(("done", None))
    except KeyboardInterrupt:
        messages.put(("done", None))
    except BaseException as error:
        messages.put(("failed", repr(error)))
        raise


def execute_in_jobs(
    todo: list[RunId],
    jobs: int,
    batch: int,
    reference: Path | None,
    checkpoints: list[int],
    bar: tqdm[Any],
    finish: Callable[[Run], None],
) -> None:
    """Split ``todo`` over ``jobs`` processes, each with its own service; this process alone writes
    the results file. A stop (SIGTERM, Ctrl-C) or a failed job stops every job."""
    context = multiprocessing.get_context("spawn")
    messages: multiprocessing.Queue[tuple[str, Any]] = context.Queue()
    workers = [
        context.Process(target=play_share, args=(todo[job::jobs], batch, reference, checkpoints, messages))
        for job in range(min(jobs, len(todo)))
    ]
    for worker in workers:
        worker.start()
    try:
        running = len(workers)
        while running:
            dead = [worker.exitcode for worker in workers if worker.exitcode not in (None, 0)]
            if dead:
                raise SystemExit(f"a job died (exit code {dead[0]}) before finishing its runs")
            try:
                kind, value = messages.get(timeout=1.0)
            except queue.Empty:
                continue
            if kind == "episodes":
                bar.update(value)
            elif kind == "run":
                finish(Run.from_record(value))
            elif kind == "done":
                running -= 1
            else:
                raise SystemExit(f"a job failed: {value}")
    except BaseException:
        for worker in workers:
            if worker.is_alive():
                worker.terminate()
        raise
    finally:
        for worker in workers:
            worker.join()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=CHECKPOINTS[-1], help="episodes per run")
    parser.add_argument("--seeds", type=int, default=5, help="runs per teacher and space; seeds 1..N")
    parser.add_argument("--teachers", default="", help="comma-separated kinds (default: every registered kind)")
    parser.add_argument("--spaces", default="2,6", help="comma-separated task-space dimensions (2 and/or 6)")
    parser.add_argument("--batch", type=int, default=1, help="tasks drawn per request")
    parser.add_argument(
        "--jobs", type=int, default=1, help="runs played at once, each job with its own service (one core each)"
    )
    parser.add_argument(
        "--teacher-param",
        action="append",
        default=[],
        metavar="KIND.NAME=VALUE",
        help="a parameter of one kind, VALUE as JSON or else a string (repeatable)",
    )
    parser.add_argument(
        "--reference",
        type=Path,
        help="teachDeepRL's teachers (and, in DIR/currot, the authors' CURROT and SPDL) to run beside ours",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("teacher_toy.jsonl"), help="results file: one JSON line per run, resumed"
    )
    parser.add_argument(
        "--in-process",
        action="store_true",
        help="play our kinds in process, without the service (same scores as --batch 1)",
    )
    parser.add_argument("--json", type=Path, help="also write every run in the results file as one JSON document")
    args = parser.parse_args()
    if min(args.episodes, args.seeds, args.batch, args.jobs) < 1:
        parser.error("--episodes, --seeds, --batch and --jobs must be at least 1")
    if args.in_process and args.batch != 1:
        parser.error("--in-process plays one task at a time: it takes no --batch")
    kinds = [k for k in args.teachers.split(",") if k] or sorted(TEACHER_KINDS)
    unknown = sorted(set(kinds) - set(TEACHER_KINDS))
    if unknown:
        parser.error(f"unknown teacher kinds {unknown}; registered: {sorted(TEACHER_KINDS)}")
    spaces = [int(d) for d in args.spaces.split(",")]
    if any(d < RELEVANT_DIMS for d in spaces):
        parser.error(f"every space needs at least {RELEVANT_DIMS} dimensions")
    params = teacher_params(args.teacher_param, parser)
    checkpoints = sorted({c for c in CHECKPOINTS if c < args.episodes} | {args.episodes})
    seeds = range(1, args.seeds + 1)
    references = {
        (dims, kind): settings
        for dims, kind in itertools.product(spaces, kinds)
        if args.reference and (settings := reference_settings(kind, dims, params.get(kind, {}))) is not None
    }

    with sole_writer(args.out):
        runs = load_runs(args.out)
        other = sorted({run.id.episodes for run in runs} - {args.episodes})
        if other:
            parser.error(f"{args.out} holds runs of {other} episodes; a file holds one --episodes: give another --out")
        planned = [
            RunId(dims, kind, "ours", seed, canonical(params.get(kind, {})), args.batch, args.episodes, args.in_process)
            for dims, kind, seed in itertools.product(spaces, kinds, seeds)
        ] + [
            RunId(dims, kind, "reference", seed, canonical(settings), 1, args.episodes)
            for (dims, kind), settings in references.items()
            for seed in seeds
        ]
        finished = {run.id for run in runs}
        todo = [run_id for run_id in planned if run_id not in finished]
        print(
            f"{args.out}: {len(runs)} runs recorded; skipping {len(planned) - len(todo)} of the {len(planned)} "
            f"runs asked for as done, {len(todo)} to go"
        )
        signal.signal(signal.SIGTERM, stop_on_sigterm)
        try:
            with tqdm(
                total=args.episodes * len(planned),
                initial=args.episodes * (len(planned) - len(todo)),
                desc="toy episodes",
                unit="ep",
                smoothing=0.05,
            ) as bar:

                def finish(run: Run) -> None:
                    append_run(args.out, run)
                    runs.append(run)
                    bar.write(describe(run))

                if args.jobs == 1:
                    execute(todo, args.batch, args.reference, checkpoints, bar, finish)
                else:
                    execute_in_jobs(todo, args.jobs, args.batch, args.reference, checkpoints, bar, finish)
        except KeyboardInterrupt:
            raise SystemExit(f"stopped; {len(runs)} runs are in {args.out}: run the same command to resume") from None

    print(summarise(runs, checkpoints))
    if args.json is not None:
        record = {
            "command": " ".join(sys.argv),
            "results": str(args.out),
            "episodes": args.episodes,
            "checkpoints": checkpoints,
            "runs": [run.record() for run in runs],
        }
        args.json.write_text(json.dumps(record, indent=1))
    print(f"every run: {args.out}")


if __name__ == "__main__":
    main()
