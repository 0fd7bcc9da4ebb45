"""Issue 80, lever 4: when the student falls, did the teacher move first, or does the teacher ease off after?

Reads one or more ``train`` run directories, finished or still training: the teacher database (every
handed-out task and its result, in the order the teacher learned them) and the metrics log (the
environment step over time, and ``eval/success_rate``: the periodic evaluations on the hardest task).
A live run's database is never opened for writing: it is copied first through SQLite's backup API from
a read-only connection, and the copy is read (an archived ``teacher.sqlite.xz`` is decompressed to a
temporary file). Per run, over training, in windows of ``--window`` consecutive results (100: two
CURROT updates of 50):

- (a) how hard the teacher's tasks are: ``distance``, the mean Euclidean distance of the window's tasks
  from the teacher's target in unit coordinates (each parameter rescaled to [0, 1]; the target is
  CURROT's ``target_box`` when it has one, so a parameter the box leaves free, KUKA's ``shaping``, does not
  count, else the space's hardest task), and per parameter its mean value in task units (the alignment
  margin in degrees) and its mean unit distance from the target;
- (b) the student's success on its own tasks in the window;
- (c) its success on the hardest task: the periodic evaluations of the metrics log.

Then which moves first. The decision rule, fixed before any real run was read:

1. Series: ``D`` (distance, a) and ``S`` (own-task success, b) per window; their first differences
   ``dD`` and ``dS``. A move *toward the target* is ``dD < 0``, its size ``M = max(-dD, 0)``; an *ease*
   is ``dD > 0``; a *fall* is ``dS < 0``, its size ``F = max(-dS, 0)``. Windows are whole (a last,
   partial one is left out); results received after the metrics log's last record (whose step is
   unknown) are left out.
2. Two Granger-style least-squares regressions with ``L`` = 3 lags (300 results), each tested by the F
   test of its ``L`` lagged coefficients of the other series against zero. They are one-sided in what
   they ask about, as lever 4 is: moves toward the target, and falls.

   - teacher -> student: ``dS[w] ~ 1 + c0 dD[w] + sum_l c_l M[w-l] + sum_l b_l dS[w-l]``. The
     contemporaneous ``c0`` takes up the immediate, mechanical effect (harder tasks in a window fail
     more in that window) and is reported, never counted; the test asks whether the teacher's *earlier*
     moves toward the target predict the student's later change, beyond that and beyond the student's
     own course.
   - student -> teacher: ``dD[w] ~ 1 + sum_l g_l F[w-l] + sum_l h_l dD[w-l]``: whether the student's
     earlier falls predict the teacher's move, beyond the teacher's own course.

3. With alpha = 0.05 for each test:

   - *the student falls after the teacher moves* (``teacher_leads``): teacher -> student has p < alpha
     and ``sum c_l < 0`` (a move toward the target is followed by a fall);
   - *the teacher eases after the student falls* (``teacher_answers``): student -> teacher has
     p < alpha and ``sum g_l > 0`` (a fall is followed by a move away from the target);
   - the verdict: ``teacher moves first`` if only the first holds, ``student falls first`` if only the
     second, ``both`` if both, ``neither`` if none, ``too short`` when a regression has fewer than
     ``MIN_DEGREES`` residual degrees of freedom. A significant test of the other sign is named in
     ``notes`` (``sum c_l > 0``: the student's success rises after a move toward the target, it adapts;
     ``sum g_l < 0``: the teacher moves on toward the target after a fall) and counts for neither.

4. The same rule, secondary, on the grid of the periodic evaluations with ``L`` = 2: ``E`` (hardest-task
   success at each evaluation) in place of ``S``, and ``D`` averaged over the results received between an
   evaluation and the one before it. The verdict is the own-task one; this one is reported beside it.

5. Described, not part of the verdict: falls marked on each success curve (own tasks: the mean of the
   next ``FALL_SPAN`` windows at least ``FALL_OWN`` below the mean of the previous ``FALL_SPAN``; the
   evaluations: the same over evaluations with ``FALL_EVAL``; runs of neighbouring candidates are one
   fall, at the steepest), and around each the teacher's move over the ``EVENT_SPAN`` windows just before
   its first window (against the ``EVENT_SPAN`` before those) and just after it: counted as a move toward
   the target before, or an ease after, when larger than the run's median absolute change of that kind,
   against the share of all window boundaries where the same holds (the baseline). The
   cross-correlations ``corr(dD[w], dS[w+l])`` at lags -L..L are plotted; the last half of training's
   linear trends (per million steps) of the evaluations, the own-task success, ``D`` and each parameter are
   listed, as the failed runs of issue 80 were told apart by them.

Post hoc, added after the first reading of the live screen run and not part of the rule (``post_hoc`` in
the JSON): the same own-task test on the windows of the last half of the steps alone (once the teacher is
near its target, ``D``'s changes are small beside the early descent's, which the whole run's test weighs
most), and with the alignment margin's mean (task units, degrees) in place of ``D``, whole run and last
half. Four more tests at 5%, read as description.

What it cannot tell: Granger precedence at the resolution of a window is not cause; a teacher that
answers within a window (CURROT updates every 50 results) shows only at lag 0, which step 2 leaves out;
20-episode evaluations every 102,400 steps are noisy, so the secondary test has little power.

    .venv/bin/python bench/falling_student.py RUN_DIR [RUN_DIR ...] --out benchmarks/bakeoff-hard/falling-student

Writes ``<run>.png`` per run (difficulty and success over steps, falls marked; the cross-correlations)
and ``summary.json`` (the rule's numbers and verdicts per run, and the windowed series).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import sqlite3
import sys
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: the checkout's packages
from bench.provenance import commit, machine  # noqa: E402
from common.client.task_space import TaskSpace  # noqa: E402
from learner.core.checkpoint import latest_checkpoint, load_checkpoint  # noqa: E402
from learner.core.figure_file import save_png  # noqa: E402
from learner.experiments.run_archive import EVALUATION_FILE, exists, metrics_records, unpacked  # noqa: E402
from learner.job.teacher_process import DATABASE_FILE  # noqa: E402
from teacher_service.curriculum_spec import stored_spec  # noqa: E402
from teacher_service.store import Store  # noqa: E402
from teacher_service.teachers.params import box_in_space  # noqa: E402

WINDOW = 100
"""Results per window: two CURROT updates (``update_every`` 50)."""
LAGS = 3
"""Lags (windows) of the Granger regressions on the own-task grid."""
EVAL_LAGS = 2
"""Lags (evaluations) of the Granger regressions on the evaluation grid."""
ALPHA = 0.05
MIN_DEGREES = 8
"""Fewest residual degrees of freedom a regression is read with; fewer: ``too short``."""
FALL_SPAN = 2
FALL_OWN = 0.10
"""A fall of own-task success: 2 windows (200 results) at least 10 points below the 2 before (about two
standard errors of the difference at a success near 50%)."""
FALL_EVAL = 0.20
"""A fall of the hardest-task evaluations: 2 evaluations at least 20 points below the 2 before (40 episodes
each side at 20 per evaluation: about two standard errors)."""
EVENT_SPAN = 2
"""Windows before and after a fall over which the teacher's move is measured."""
TRACKED = "align_margin"
"""The parameter named beside the distance in the plot and the last-half trends, as issue 80 names it."""

VERDICTS = ("teacher moves first", "student falls first", "both", "neither", "too short")


def copy_database(path: Path, target: Path) -> None:
    """A consistent copy of a (possibly live) SQLite database, read through a read-only connection."""
    source = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)
    try:
        destination = sqlite3.connect(target)
        try:
            source.backup(destination)
        finally:
            destination.close()
    finally:
        source.close()


@contextlib.contextmanager
def database_copy(run_dir: Path) -> Iterator[Path]:
    """The run's teacher database as a private copy, removed afterwards: a raw one copied through the
    backup API (training may be writing it), a compressed one decompressed."""
    raw = run_dir / DATABASE_FILE
    if raw.exists():
        with tempfile.TemporaryDirectory(prefix="falling-student-") as scratch:
            copy = Path(scratch) / DATABASE_FILE
            copy_database(raw, copy)
            yield copy
        return
    with unpacked(raw) as copy:
        yield copy


def target_box(spec: dict[str, Any], space: TaskSpace) -> tuple[np.ndarray, np.ndarray, str]:
    """The teacher's target in unit coordinates (low and high corners) and how it was chosen."""
    params = spec.get("params", {})
    if params.get("target_box"):
        low, high = box_in_space("target_box", params["target_box"], space)
        return low, high, f"target_box {json.dumps(params['target_box'])}, other parameters at their hardest"
    hardest = space.to_unit(space.to_array(space.hardest()))
    return hardest, hardest, "the space's hardest task"


def distance_to_box(unit: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """(n, d): each coordinate's distance from the box's interval, 0 inside it."""
    result: np.ndarray = np.maximum(low - unit, 0.0) + np.maximum(unit - high, 0.0)
    return result


def superseded_dropped(records: Sequence[dict[str, Any]]) -> tuple[list[dict[str, Any]], list[int]]:
    """The records of the attempt that counts: where the step goes back (a resume from an earlier
    checkpoint), records of the abandoned attempt at or past that step are dropped. Also the steps the
    run resumed at."""
    kept: list[dict[str, Any]] = []
    resumes = []
    for record in records:
        if kept and record["step"] <= kept[-1]["step"]:
            resumes.append(int(record["step"]))
            while kept and kept[-1]["step"] >= record["step"]:
                kept.pop()
        kept.append(record)
    return kept, resumes


@dataclass
class Run:
    """One run's results in the teacher's order, and its metrics."""

    name: str
    path: str
    teacher: str
    target: str
    space: TaskSpace
    values: np.ndarray
    """(results, parameters): each task in task units."""
    offsets: np.ndarray
    """(results, parameters): each task's unit distance from the target per parameter."""
    success: np.ndarray
    reward: np.ndarray
    step: np.ndarray
    """The environment step at which the result was received (interpolated on the metrics log's times)."""
    eval_steps: np.ndarray
    eval_success: np.ndarray
    last_step: int
    finished: bool
    """Whether the run holds its final evaluation (``evaluation.json``, a bake-off's)."""
    resumes: list[int]
    late_results: int
    """Results received after the metrics log's last record, left out."""
    database_read_at: str

    @property
    def distance(self) -> np.ndarray:
        result: np.ndarray = np.linalg.norm(self.offsets, axis=1)
        return result


def load_run(run_dir: Path) -> Run:
    """A run's results and metrics; ``ValueError`` says why a run cannot be read."""
    records = metrics_records(run_dir)
    if len(records) < 2:
        raise ValueError("its metrics log holds fewer than two records")
    read_at = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    with database_copy(run_dir) as database:
        store = Store(database)
        try:
            curricula = store.curricula()
            if len(curricula) != 1:
                raise ValueError(f"its teacher database holds {len(curricula)} curricula, not one")
            [curriculum] = curricula
            results = list(store.results(curriculum.id))
        finally:
            store.close()
    space = stored_spec(curriculum.spec).task_space()
    spec = json.loads(curriculum.spec)
    low, high, target = target_box(spec, space)
    times = np.array([record["time"] for record in records], dtype=np.float64)
    if np.any(np.diff(times) < 0):
        raise ValueError("its metrics log's times go back")
    received = np.array([result.received_at for result in results], dtype=np.float64)
    within = received <= times[-1]
    results = [result for result, keep in zip(results, within, strict=True) if keep]
    values = np.array([space.to_array(result.task) for result in results]).reshape(-1, len(space))
    kept, resumes = superseded_dropped(records)
    evaluations = [r for r in kept if r.get("eval/success_rate") is not None]
    return Run(
        name=run_dir.name,
        path=str(run_dir),
        teacher=str(spec["teacher"]),
        target=target,
        space=space,
        values=values,
        offsets=distance_to_box(space.to_unit(values), low, high),
        success=np.array([bool(result.success) for result in results], dtype=bool),
        reward=np.array([result.reward for result in results], dtype=np.float64),
        step=np.interp(received[within], times, [record["step"] for record in records]),
        eval_steps=np.array([r["step"] for r in evaluations], dtype=np.int64),
        eval_success=np.array([r["eval/success_rate"] for r in evaluations], dtype=np.float64),
        last_step=int(kept[-1]["step"]),
        finished=trained_to_budget(run_dir),
        resumes=resumes,
        late_results=int((~within).sum()),
        database_read_at=read_at,
    )


def trained_to_budget(run_dir: Path) -> bool:
    """Whether the run is over: its bake-off evaluated it, or its last checkpoint holds its whole budget,
    counted as the trainer counts it (``Counters.budget_spent``; a screen's runs, evaluated into other files)."""
    if exists(run_dir / EVALUATION_FILE):
        return True
    latest = latest_checkpoint(run_dir)
    if latest is None:
        return False
    checkpoint = load_checkpoint(latest)
    return checkpoint.budget_spent >= checkpoint.config.total_steps


@dataclass
class Windows:
    """A run's per-window series."""

    size: int
    first: np.ndarray
    """Index of each window's first result."""
    step: np.ndarray
    """Median step of the window's results."""
    step_end: np.ndarray
    distance: np.ndarray
    success: np.ndarray
    reward: np.ndarray
    values: np.ndarray
    """(windows, parameters): mean task-unit value."""
    offsets: np.ndarray
    """(windows, parameters): mean unit distance from the target."""
    evaluation: np.ndarray
    """The latest evaluation at or before the window's last step (NaN before the first)."""


def windows(run: Run, size: int = WINDOW) -> Windows:
    count = len(run.success) // size
    cut = count * size

    def per_window(values: np.ndarray) -> np.ndarray:
        shaped = values[:cut].reshape(count, size, *values.shape[1:])
        result: np.ndarray = shaped.mean(axis=1)
        return result

    step_end = run.step[:cut].reshape(count, size).max(axis=1) if count else np.empty(0)
    latest = np.searchsorted(run.eval_steps, step_end, side="right") - 1
    evaluation = np.full(count, np.nan)
    if len(run.eval_success):
        evaluation = np.where(latest >= 0, run.eval_success[np.maximum(latest, 0)], np.nan)
    return Windows(
        size=size,
        first=np.arange(count) * size,
        step=np.median(run.step[:cut].reshape(count, size), axis=1) if count else np.empty(0),
        step_end=step_end,
        distance=per_window(run.distance),
        success=per_window(run.success.astype(np.float64)),
        reward=per_window(run.reward),
        values=per_window(run.values),
        offsets=per_window(run.offsets),
        evaluation=evaluation,
    )


@dataclass
class Regression:
    """One Granger-style test: do ``lags`` past values of ``x`` predict ``y`` beyond ``y``'s own past (and
    a contemporaneous regressor's present value)?"""

    f: float
    p: float
    lagged_sum: float
    """Sum of the coefficients of ``x``'s lags."""
    lagged: list[float]
    immediate: float | None
    """Coefficient of the contemporaneous regressor (None without one)."""
    rows: int
    degrees: int


def lagged_test(
    y: np.ndarray, x: np.ndarray, lags: int, contemporaneous: np.ndarray | None = None
) -> Regression | None:
    """Regress ``y[t]`` on a constant, ``y``'s ``lags`` past values, ``contemporaneous[t]`` if given and ``x``'s
    ``lags`` past values; F-test the last against zero. None when fewer than ``MIN_DEGREES`` residual degrees
    of freedom are left."""
    present = np.zeros(len(y)) if contemporaneous is None else contemporaneous
    finite = np.isfinite(y) & np.isfinite(x) & np.isfinite(present)
    rows = [t for t in range(lags, len(y)) if finite[t - lags : t + 1].all()]
    index = np.array(rows, dtype=np.int64)
    own = [np.ones(len(index))] + [y[index - lag] for lag in range(1, lags + 1)]
    if contemporaneous is not None:
        own.append(present[index])
    other = [x[index - lag] for lag in range(1, lags + 1)]
    restricted, full = np.column_stack(own), np.column_stack(own + other)
    degrees = len(index) - full.shape[1]
    if degrees < MIN_DEGREES:
        return None
    target = y[index]
    coefficients, *_ = np.linalg.lstsq(full, target, rcond=None)
    residual_full = float(np.sum((target - full @ coefficients) ** 2))
    restricted_coefficients, *_ = np.linalg.lstsq(restricted, target, rcond=None)
    residual_restricted = float(np.sum((target - restricted @ restricted_coefficients) ** 2))
    if residual_full <= 0.0:
        f_value, p_value = float("inf"), 0.0
    else:
        f_value = ((residual_restricted - residual_full) / lags) / (residual_full / degrees)
        p_value = float(stats.f.sf(f_value, lags, degrees))
    lagged = [float(value) for value in coefficients[-lags:]]
    return Regression(
        f=float(f_value),
        p=p_value,
        lagged_sum=float(sum(lagged)),
        lagged=lagged,
        immediate=float(coefficients[lags + 1]) if contemporaneous is not None else None,
        rows=len(index),
        degrees=degrees,
    )


@dataclass
class Verdict:
    verdict: str
    teacher_leads: bool
    teacher_answers: bool
    notes: list[str] = field(default_factory=list)
    teacher_to_student: Regression | None = None
    student_to_teacher: Regression | None = None


def decide(difficulty: np.ndarray, success: np.ndarray, lags: int) -> Verdict:
    """The docstring's rule on one grid: ``difficulty`` (distance to target) and ``success`` per point."""
    d_difficulty, d_success = np.diff(difficulty), np.diff(success)
    toward, fall = np.maximum(-d_difficulty, 0.0), np.maximum(-d_success, 0.0)
    forward = lagged_test(d_success, toward, lags, contemporaneous=d_difficulty)
    backward = lagged_test(d_difficulty, fall, lags)
    if forward is None or backward is None:
        return Verdict("too short", False, False, [], forward, backward)
    leads = forward.p < ALPHA and forward.lagged_sum < 0
    answers = backward.p < ALPHA and backward.lagged_sum > 0
    notes = []
    if forward.p < ALPHA and forward.lagged_sum >= 0:
        notes.append("the student's success rises after a move toward the target (it adapts)")
    if backward.p < ALPHA and backward.lagged_sum <= 0:
        notes.append("the teacher moves on toward the target after a fall")
    verdict = "both" if leads and answers else VERDICTS[0] if leads else VERDICTS[1] if answers else "neither"
    return Verdict(verdict, leads, answers, notes, forward, backward)


def cross_correlations(difficulty: np.ndarray, success: np.ndarray, lags: int) -> dict[int, float]:
    """``corr(dD[w], dS[w + l])`` for l in -lags..lags: positive l, the difficulty's change comes first."""
    d_difficulty, d_success = np.diff(difficulty), np.diff(success)
    result = {}
    for lag in range(-lags, lags + 1):
        a = d_difficulty[max(0, -lag) : len(d_difficulty) - max(0, lag)]
        b = d_success[max(0, lag) : len(d_success) - max(0, -lag)]
        ok = len(a) > 2 and np.std(a) > 0 and np.std(b) > 0
        result[lag] = float(np.corrcoef(a, b)[0, 1]) if ok else float("nan")
    return result


def falls(series: np.ndarray, drop: float, span: int = FALL_SPAN) -> list[int]:
    """Indices k where the mean of ``series[k : k + span]`` is at least ``drop`` below that of
    ``series[k - span : k]``; a run of neighbouring such k is one fall, at its steepest."""
    candidates = []
    for k in range(span, len(series) - span + 1):
        change = series[k : k + span].mean() - series[k - span : k].mean()
        if change <= -drop:
            candidates.append((k, change))
    marked: list[int] = []
    previous, steepest = -2, 0.0
    for k, change in candidates:
        if k == previous + 1:
            if change < steepest:
                marked[-1], steepest = k, change
        else:
            marked.append(k)
            steepest = change
        previous = k
    return marked


def evaluation_grid(run: Run) -> tuple[np.ndarray, np.ndarray]:
    """Per evaluation: the mean distance of the results received since the one before, and its success."""
    bounds = np.concatenate([[-np.inf], run.eval_steps.astype(np.float64)])
    difficulty = np.full(len(run.eval_steps), np.nan)
    for k in range(len(run.eval_steps)):
        chosen = (run.step > bounds[k]) & (run.step <= bounds[k + 1])
        if chosen.any():
            difficulty[k] = run.distance[chosen].mean()
    return difficulty, run.eval_success


def teacher_around(distance: np.ndarray, boundary: int) -> tuple[float, float] | None:
    """The teacher's move just before a boundary (window ``boundary`` the first after it) and just after."""
    span = EVENT_SPAN
    if boundary - 2 * span < 0 or boundary + span > len(distance):
        return None
    before = distance[boundary - span : boundary].mean() - distance[boundary - 2 * span : boundary - span].mean()
    after = distance[boundary : boundary + span].mean() - distance[boundary - span : boundary].mean()
    return float(before), float(after)


def event_study(distance: np.ndarray, boundaries: Sequence[int]) -> dict[str, Any]:
    """Around each fall: did the teacher move toward the target just before, or ease just after, against
    every window boundary of the run (the baseline)?"""
    everywhere = [teacher_around(distance, b) for b in range(len(distance) + 1)]
    base = np.array([pair for pair in everywhere if pair is not None]).reshape(-1, 2)
    if not len(base):
        return {"falls": len(boundaries), "counted": 0}
    threshold_before, threshold_after = np.median(np.abs(base[:, 0])), np.median(np.abs(base[:, 1]))
    around = [(b, teacher_around(distance, b)) for b in boundaries]
    counted = [(b, pair) for b, pair in around if pair is not None]
    moved = [pair[0] < -threshold_before for _, pair in counted]
    eased = [pair[1] > threshold_after for _, pair in counted]
    return {
        "falls": len(boundaries),
        "counted": len(counted),
        "moved_toward_target_before": int(sum(moved)),
        "eased_after": int(sum(eased)),
        "baseline_moved_toward_target_before": float(np.mean(base[:, 0] < -threshold_before)),
        "baseline_eased_after": float(np.mean(base[:, 1] > threshold_after)),
        "threshold_before": float(threshold_before),
        "threshold_after": float(threshold_after),
        "per_fall": [
            {"window": int(b), "distance_change_before": pair[0], "distance_change_after": pair[1]}
            for b, pair in counted
        ],
    }


def trend(steps: np.ndarray, values: np.ndarray) -> float | None:
    """Least-squares slope per million steps; None with fewer than 3 finite points."""
    ok = np.isfinite(values)
    if ok.sum() < 3 or np.ptp(steps[ok]) == 0:
        return None
    return float(np.polyfit(steps[ok] / 1e6, values[ok], 1)[0])


def regression_json(regression: Regression | None) -> dict[str, Any] | None:
    if regression is None:
        return None
    return {
        "f": regression.f,
        "p": regression.p,
        "lagged_sum": regression.lagged_sum,
        "lagged": regression.lagged,
        "immediate": regression.immediate,
        "rows": regression.rows,
        "degrees_of_freedom": regression.degrees,
    }


def verdict_json(verdict: Verdict) -> dict[str, Any]:
    return {
        "verdict": verdict.verdict,
        "teacher_leads": verdict.teacher_leads,
        "teacher_answers": verdict.teacher_answers,
        "notes": verdict.notes,
        "teacher_to_student": regression_json(verdict.teacher_to_student),
        "student_to_teacher": regression_json(verdict.student_to_teacher),
    }


def rounded(values: np.ndarray, digits: int = 4) -> list[float | None]:
    return [None if not np.isfinite(v) else round(float(v), digits) for v in values]


@dataclass
class Analysis:
    run: Run
    grid: Windows
    own: Verdict
    evaluations: Verdict
    correlations: dict[int, float]
    own_falls: list[int]
    eval_falls: list[int]
    """Evaluation indices k: the fall lies between evaluation k - 1 and k."""
    eval_fall_windows: list[int]
    own_events: dict[str, Any]
    eval_events: dict[str, Any]


def analyse(run: Run, size: int = WINDOW) -> Analysis:
    grid = windows(run, size)
    difficulty, evaluation = evaluation_grid(run)
    eval_falls = falls(evaluation, FALL_EVAL)
    boundary_steps = [(run.eval_steps[k - 1] + run.eval_steps[k]) / 2 for k in eval_falls]
    eval_windows = [int(np.searchsorted(grid.step_end, step, side="left")) for step in boundary_steps]
    own_falls = falls(grid.success, FALL_OWN)
    return Analysis(
        run=run,
        grid=grid,
        own=decide(grid.distance, grid.success, LAGS),
        evaluations=decide(difficulty, evaluation, EVAL_LAGS),
        correlations=cross_correlations(grid.distance, grid.success, LAGS),
        own_falls=own_falls,
        eval_falls=eval_falls,
        eval_fall_windows=eval_windows,
        own_events=event_study(grid.distance, own_falls),
        eval_events=event_study(grid.distance, eval_windows),
    )


def post_hoc(analysis: Analysis) -> dict[str, Any]:
    """The docstring's post hoc tests: the own-task rule on the last half's windows, and with ``TRACKED`` in
    place of the distance."""
    run, grid = analysis.run, analysis.grid
    late = grid.step >= run.last_step / 2
    signals = {"distance": grid.distance}
    if TRACKED in run.space.names:
        signals[TRACKED] = grid.values[:, run.space.names.index(TRACKED)]
    result: dict[str, Any] = {"last_half_windows": int(late.sum())}
    for name, signal in signals.items():
        if name != "distance":
            result[f"{name}_whole_run"] = verdict_json(decide(signal, grid.success, LAGS))
        result[f"{name}_last_half"] = verdict_json(decide(signal[late], grid.success[late], LAGS))
    return result


def last_half(analysis: Analysis) -> dict[str, Any]:
    """Linear trends over the second half of the steps trained so far, and the last tenth's means."""
    run, grid = analysis.run, analysis.grid
    late = grid.step >= run.last_step / 2
    late_eval = run.eval_steps >= run.last_step / 2
    tail = grid.step >= 0.9 * run.last_step
    return {
        "from_step": run.last_step // 2,
        "per_million_steps": {
            "evaluation_success": trend(run.eval_steps[late_eval].astype(np.float64), run.eval_success[late_eval]),
            "own_success": trend(grid.step[late], grid.success[late]),
            "distance": trend(grid.step[late], grid.distance[late]),
            **{name: trend(grid.step[late], grid.values[late, i]) for i, name in enumerate(run.space.names)},
        },
        "last_tenth": {
            "windows": int(tail.sum()),
            "own_success": float(grid.success[tail].mean()) if tail.any() else None,
            "distance": float(grid.distance[tail].mean()) if tail.any() else None,
            **{
                name: float(grid.values[tail, i].mean()) if tail.any() else None
                for i, name in enumerate(run.space.names)
            },
        },
    }


def summary(analysis: Analysis) -> dict[str, Any]:
    run, grid = analysis.run, analysis.grid
    return {
        "run": run.name,
        "path": run.path,
        "teacher": run.teacher,
        "target": run.target,
        "database_read_at": run.database_read_at,
        "last_step": run.last_step,
        "finished": run.finished,
        "resumed_at_steps": run.resumes,
        "results": len(run.success),
        "results_after_last_metrics_record_left_out": run.late_results,
        "evaluations": len(run.eval_steps),
        "windows": len(grid.step),
        "window_results": grid.size,
        "verdict": analysis.own.verdict,
        "own_tasks": verdict_json(analysis.own),
        "evaluation_grid": verdict_json(analysis.evaluations),
        "cross_correlation_dD_dS": {str(lag): value for lag, value in analysis.correlations.items()},
        "own_task_falls": {
            "steps": [float(grid.step[k]) for k in analysis.own_falls],
            **analysis.own_events,
        },
        "evaluation_falls": {
            "steps": [float((run.eval_steps[k - 1] + run.eval_steps[k]) / 2) for k in analysis.eval_falls],
            **analysis.eval_events,
        },
        "last_half": last_half(analysis),
        "post_hoc": post_hoc(analysis),
        "series": {
            "step": rounded(grid.step, 0),
            "distance": rounded(grid.distance),
            "own_success": rounded(grid.success),
            "evaluation_success": rounded(grid.evaluation),
            "mean_value": {name: rounded(grid.values[:, i]) for i, name in enumerate(run.space.names)},
            "mean_unit_distance": {name: rounded(grid.offsets[:, i]) for i, name in enumerate(run.space.names)},
        },
        "evaluations_raw": {"step": run.eval_steps.tolist(), "success": rounded(run.eval_success)},
    }


def plot(analysis: Analysis, out: Path) -> Path:
    """Difficulty and success over steps with the falls marked, and the cross-correlations."""
    run, grid = analysis.run, analysis.grid
    figure = Figure(figsize=(12, 10), layout="constrained")
    top, middle, bottom = figure.subplots(3, 1, height_ratios=(3, 3, 2))
    top.plot(grid.step, grid.distance, color="tab:blue", label="distance to target (unit, mean)")
    top.set_ylabel("distance to target (unit, log)", color="tab:blue")
    if len(grid.distance) and grid.distance.min() > 0:
        top.set_yscale("log")  # near the target the late changes are a hundredth of the early descent's
    if TRACKED in run.space.names:
        column = run.space.names.index(TRACKED)
        right = top.twinx()
        right.plot(grid.step, grid.values[:, column], color="tab:orange", label=f"{TRACKED} (mean)")
        hardest = run.space.parameters[column].hardest
        if hardest is not None:
            right.axhline(hardest, color="tab:orange", linestyle=":", linewidth=1)
        right.set_yscale("log")
        right.set_ylabel(f"{TRACKED}, task units (log)", color="tab:orange")
    middle.plot(grid.step, grid.success, color="tab:green", label="own-task success (window)")
    middle.plot(run.eval_steps, run.eval_success, color="black", marker=".", label="hardest-task evaluation")
    middle.set_ylim(0, 1.02)
    middle.set_ylabel("success rate")
    for axes in (top, middle):
        for k in analysis.own_falls:
            axes.axvline(grid.step[k], color="tab:red", linestyle="--", linewidth=1)
        for k in analysis.eval_falls:
            axes.axvline((run.eval_steps[k - 1] + run.eval_steps[k]) / 2, color="tab:purple", linestyle=":")
        axes.grid(alpha=0.3)
        axes.set_xlim(0, max(run.last_step, 1))
    middle.plot([], [], color="tab:red", linestyle="--", label="own-task fall")
    middle.plot([], [], color="tab:purple", linestyle=":", label="evaluation fall")
    middle.legend(loc="lower right", fontsize="small")
    middle.set_xlabel("environment steps")
    top.set_title(
        f"{run.name}: {len(run.success):_} results to step {run.last_step:_}"
        f"{'' if run.finished else ' (unfinished)'}; windows of {grid.size}"
    )
    lags = list(analysis.correlations)
    bottom.bar(lags, [analysis.correlations[lag] for lag in lags], color="tab:gray")
    if len(grid.step) > 3:
        band = 2 / np.sqrt(len(grid.step) - 1)
        bottom.axhspan(-band, band, color="tab:blue", alpha=0.1)
    bottom.axhline(0, color="black", linewidth=0.5)
    bottom.set_xlabel("lag l in windows (l > 0: the distance's change comes first)")
    bottom.set_ylabel("corr(dD[w], dS[w+l])")
    forward, backward = analysis.own.teacher_to_student, analysis.own.student_to_teacher
    detail = (
        f"teacher -> student p = {forward.p:.3f} (sum c {forward.lagged_sum:+.3f}), student -> teacher "
        f"p = {backward.p:.3f} (sum g {backward.lagged_sum:+.3f})"
        if forward and backward
        else "too few windows for the regressions"
    )
    bottom.set_title(
        f"own tasks: {analysis.own.verdict}; evaluations: {analysis.evaluations.verdict}\n{detail}", fontsize="medium"
    )
    bottom.grid(alpha=0.3)
    path = out / f"{run.name}.png"
    save_png(figure, path, dpi=80)
    return path


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run directories (teacher.sqlite[.xz] and metrics.jsonl)")
    parser.add_argument("--out", type=Path, required=True, help="directory for <run>.png and summary.json")
    parser.add_argument("--window", type=int, default=WINDOW, help=f"results per window (default {WINDOW})")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    entries: list[dict[str, Any]] = []
    for run_dir in args.runs:
        if not exists(run_dir / DATABASE_FILE):
            entries.append({"run": run_dir.name, "path": str(run_dir), "skipped": "no teacher database"})
            continue
        try:
            run = load_run(run_dir)
        except ValueError as error:
            entries.append({"run": run_dir.name, "path": str(run_dir), "skipped": str(error)})
            continue
        analysis = analyse(run, args.window)
        entry = summary(analysis)
        entry["plot"] = plot(analysis, args.out).name if len(analysis.grid.step) else None
        entries.append(entry)
    document = {
        "generated": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "command": " ".join(["bench/falling_student.py", *(argv if argv is not None else sys.argv[1:])]),
        "commit": commit(),
        "machine": machine(),
        "rule": {
            "window_results": args.window,
            "lags": LAGS,
            "evaluation_lags": EVAL_LAGS,
            "alpha": ALPHA,
            "fall_own": FALL_OWN,
            "fall_evaluation": FALL_EVAL,
            "fall_span": FALL_SPAN,
            "event_span": EVENT_SPAN,
            "text": "bench/falling_student.py's docstring",
        },
        "runs": entries,
    }
    (args.out / "summary.json").write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
    for entry in entries:
        if "skipped" in entry:
            print(f"{entry['run']}: skipped, {entry['skipped']}")
        else:
            print(
                f"{entry['run']}: {entry['results']:_} results to step {entry['last_step']:_}, {entry['windows']} "
                f"windows: own tasks {entry['verdict']}, evaluations {entry['evaluation_grid']['verdict']}"
            )
    return document


if __name__ == "__main__":
    main()
