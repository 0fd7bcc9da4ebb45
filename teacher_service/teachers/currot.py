"""CURROT (Klink et al. 2022, "Curriculum Reinforcement Learning via Constrained Optimal Transport").

The teacher: it keeps the particles, the success buffer and the failures, counts results, lets
an update fall due every ``update_every`` results and saves and restores its state. The update
itself, and where it departs from the authors' code, is ``teachers.algorithms.currot``.

The measure: while every result so far reported ``success``, the estimate is a success rate held
to ``success_delta``; otherwise it is the return held to ``delta``. Without ``delta`` (the default)
the return bar is ``success_delta`` of the way from the lowest to the highest return seen so far,
and no result meets it until two different returns were seen, so the defaults work on any reward
scale. ``train`` passes 5.0 for KUKA (a grasp is worth about +10, a failure ends around -2..+2).

On the ALP-GMM paper's toy this masters as much of the space as the authors' code, seed for seed
within noise (docs/results/parity.md). There only the corner cube pays at first, and a uniform cloud
can miss it: the noisy resampling of the update is what finds it.

When it helps: a student that learns nothing from the hardest tasks but can be led there through
tasks it already half masters, in spaces where the way to the target is not a straight line;
unlike SPDL's Gaussian, the particle cloud can take any shape.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from collections.abc import Callable, Mapping
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator
from scipy.special import ndtri

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.algorithms.currot import (
    WHY,
    FitInputs,
    ParticleFit,
    TargetBox,
    move_particles,
    update_successes,
)
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.draws import FIT_STREAM, TASK_STREAM, indexed_seed, indexed_uniforms
from teacher_service.teachers.params import FiniteFloat, TaskBox, TeacherParams, box_in_space, check_target_box
from teacher_service.teachers.performance import RETURN_SCALE, UNKNOWN_SUCCESS, ReturnScale
from teacher_service.teachers.row_log import RowLog
from teacher_service.teachers.state import BOOL, FLOAT, INT, PLAIN, FloatArray, Items, Optional, StateField

MAX_PARTICLES = 500
MAX_BUFFER = 2000
MAX_CANDIDATES = 128
"""Together these bound one update: at most 500 x 128 points estimated from their nearest among
2,500 buffered results (or 2,000 recent ones), and assignments of at most 500 particles to at most
2,500 tasks."""

DEFAULT_RECENT = 400
"""Results the estimate is fitted to with ``estimate`` = recent, unless ``recent_results`` says."""

MAX_PENDING_FITS = 4
"""Due fits whose inputs are kept for ``refit_job``; an older one is superseded."""

RECENT_MOVES = 100
"""Updates the state reports in ``moves``."""


class CurrotParams(TeacherParams):
    particles: int = Field(default=200, ge=2, le=MAX_PARTICLES)
    """Task particles; tasks are drawn from them. The success buffer holds as many. The authors
    used 100 to 500."""
    update_every: int = Field(default=50, ge=1, le=10_000)
    """Results between two particle updates (the authors: 50 episodes)."""
    buffer_size: int | None = Field(default=None, ge=1, le=MAX_BUFFER)
    """Recent failures the performance estimate keeps beside the success buffer (once the
    particles' estimate has first reached the bar); null: as many as there are particles (the
    authors')."""
    max_move: float = Field(default=0.05, gt=0.0, le=1.0)
    """Longest move of a particle in one update, as a share of the box's diagonal (in the units of
    ``distances``)."""
    delta: FiniteFloat | None = Field(default=None, ge=-1e9, le=1e9)
    """The bar on the estimated return, for results without ``success``. Null: ``success_delta`` of
    the way from the lowest to the highest return seen so far (none meets it until two different
    returns were seen), so any reward scale works. KUKA (``train``): 5, a grasp being worth about +10."""
    success_delta: float = Field(default=0.5, ge=0.0, le=1.0)
    """The bar on the estimated success rate, used while every result reports ``success``; without
    ``delta``, also the share of the returns' range seen that the return bar lies at."""
    candidates: int = Field(default=100, ge=1, le=MAX_CANDIDATES)
    """Points tried in the ball around each particle per update (the authors: 100)."""
    noise: float = Field(default=0.001, ge=0.0, le=0.5)
    """Half-width of the uniform noise added to a particle to make a task, per dimension in units of
    the dimension's width (the authors: 0.001)."""
    target: Literal["uniform", "hardest", "box"] = "uniform"
    """Where the particles head: samples of the uniform distribution over the box, the space's
    hardest task, or samples of the uniform distribution over ``target_box``."""
    target_box: TaskBox | None = None
    """With ``target`` = box (and only then): parameter name to [low, high] in task units; a
    parameter not named is held at its hardest value, and [a, a] holds it at a. For a parameter
    that success does not depend on (KUKA's ``shaping``), ``{"shaping": [0, 1]}`` leads every other
    parameter to its hardest value and leaves that one free."""
    start: Literal["uniform", "easiest"] = "uniform"
    """Where the particles start: uniform over the box (as in the authors' experiments), or near the
    space's easiest task."""
    start_spread: float = Field(default=0.1, ge=0.0, le=10.0)
    """With ``start`` = easiest: standard deviation of the particles around it, per dimension in
    units of the dimension's width, clipped to the box."""
    below_bar: Literal["jump", "walk"] = "jump"
    """A particle estimated below the bar jumps to its sample of the success buffer (the authors'),
    or walks at most ``max_move`` toward it (cost measured on the toy: see ``teachers.algorithms.currot``)."""
    distances: Literal["unit", "raw"] = "unit"
    """Distances measured in the box rescaled to [0, 1] per dimension, or in the task's own units
    (the authors')."""
    estimate: Literal["buffers", "recent"] = "buffers"
    """What the performance estimate is fitted to. "buffers": the success buffer and the recent
    failures (the authors'). "recent": the last ``recent_results`` results only, successes and
    failures alike, as they came, so a student whose success rate at a place is below the bar is
    estimated below it there, whatever successes the buffer still holds from before; a particle
    below the bar is then replaced only by a sample estimated at or above it (see
    ``teachers.algorithms.currot``)."""
    recent_results: int = Field(default=DEFAULT_RECENT, ge=1, le=MAX_BUFFER)
    """With ``estimate`` = recent (and only then): how many of the latest results the estimate is
    fitted to."""

    @model_validator(mode="after")
    def _consistent(self) -> CurrotParams:
        check_target_box(self.target, self.target_box)
        if self.estimate != "recent" and self.recent_results != DEFAULT_RECENT:
            raise ValueError(f"recent_results is read only with estimate 'recent', not {self.estimate!r}")
        return self


class CurrotTeacher(Teacher):
    """Task particles moved toward a target by constrained optimal transport, kept where the student
    is estimated to reach the bar: a success rate of ``success_delta`` while results carry
    ``success``, else a return of ``delta``, or without it ``success_delta`` of the way through the
    returns seen (see the module docstring)."""

    kind = "currot"
    Params = CurrotParams
    params: CurrotParams
    state_fields = (
        StateField("fits_requested", INT),
        StateField("fits_installed", INT),
        StateField("successes", FloatArray("the success buffer", rows=True), "_successes"),
        StateField("failures", FloatArray("the kept failures", rows=True), "_failures"),
        StateField("buffer_reached", BOOL, "_buffer_reached"),
        StateField("threshold_reached", BOOL, "_threshold_reached"),
        StateField("floor", Optional(Items(FLOAT)), "_floor"),
        StateField("every_success", BOOL, "_every_success"),
        StateField("returns_seen", RETURN_SCALE, "_returns"),
        StateField("moves", Items(PLAIN), "_moves"),
    )

    def __init__(self, space: TaskSpace, seed: int, params: CurrotParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        dims, count = len(space), self.params.particles
        if self.params.target_box is not None:
            self._target = TargetBox(*box_in_space("target_box", self.params.target_box, space))
        elif self.params.target == "hardest":
            hardest = self._anchor("target", space.hardest)
            self._target = TargetBox(hardest, hardest)
        else:
            self._target = TargetBox(np.zeros(dims), np.ones(dims))
        start = indexed_uniforms(seed, FIT_STREAM, 0, count, dims)
        if self.params.start == "easiest":
            easiest = self._anchor("start", space.easiest)
            start = np.clip(easiest + self.params.start_spread * ndtri(start + 2.0**-54), 0.0, 1.0)
        self._particles = start
        widths = np.where(space.high > space.low, space.high - space.low, 1.0)
        self._scale = widths if self.params.distances == "raw" else np.ones(dims)
        self._fit: ParticleFit | None = None
        self._log = RowLog(dims + 2, 2 * self.params.update_every)
        self.fits_requested = 0
        self.fits_installed = 0
        self._pending: dict[int, FitInputs] = {}
        self._moves: deque[dict[str, Any]] = deque(maxlen=RECENT_MOVES)
        # The lasting state the authors' buffer keeps, updated as each fit falls due.
        self._successes = np.empty((0, dims + 2))
        """The success buffer: unit task, reward, success (``UNKNOWN_SUCCESS`` when not reported)."""
        self._failures = np.empty((0, dims + 2))
        self._window = np.empty((0, dims + 2))
        """With ``estimate`` = recent: the latest ``recent_results`` results, rows as the log's."""
        self._buffer_reached = False
        self._threshold_reached = False
        self._floor: list[float] | None = None
        """The lowest reward and success of the first update's results."""
        self._every_success = True
        """Whether every result so far reported ``success``."""
        self._returns = ReturnScale()

    def _anchor(self, name: str, anchor: Callable[[], Task]) -> np.ndarray:
        try:
            unit: np.ndarray = self.space.to_unit(self.space.to_array(anchor()))
        except ValueError as error:
            raise ValueError(f"{name}: {error}") from None
        return unit

    @property
    def radius(self) -> float:
        """The longest move: ``max_move`` times the diagonal of the box (in ``distances`` units)."""
        return self.params.max_move * float(np.linalg.norm(self._scale))

    @property
    def failures_kept(self) -> int:
        return self.params.particles if self.params.buffer_size is None else self.params.buffer_size

    def _draw(self, first_index: int, count: int) -> list[Task]:
        dims, particles = len(self.space), self._particles
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, 1 + dims)
        picked = np.minimum((uniforms[:, 0] * len(particles)).astype(np.int64), len(particles) - 1)
        units = np.clip(particles[picked] + self.params.noise * (2.0 * uniforms[:, 1:] - 1.0), 0.0, 1.0)
        return [self.space.from_array(row) for row in self.space.from_unit(units)]

    def _bar(self) -> tuple[str, float | None]:
        """The measure and the bar an update falling due now holds the estimate to."""
        if self._every_success:
            return "success", self.params.success_delta
        if self.params.delta is not None:
            return "return", self.params.delta
        return "return", self._returns.at(self.params.success_delta)

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        success = UNKNOWN_SUCCESS if result.success is None else float(result.success)
        unit = self.space.to_unit(self.space.to_array(result.task))
        self._log.append(np.concatenate([unit, (result.reward, success)]))
        self._returns.see(result.reward)
        self._every_success &= result.success is not None
        if self.results_seen % self.params.update_every:
            return None
        self.fits_requested += 1
        index = self.fits_requested - 1
        self._pending[index] = self._fall_due(index, self._log.view(self.results_seen - self.params.update_every))
        for stale in sorted(self._pending)[:-MAX_PENDING_FITS]:
            del self._pending[stale]
        self._log.needed_from = self.results_seen
        return self.refit_job(index)

    def _fall_due(self, index: int, batch: np.ndarray) -> FitInputs:
        """Take the batch since the last update into the success buffer and the kept failures (the
        authors' bookkeeping, cheap and sequential), and fix what update ``index`` starts from."""
        measure, bar = self._bar()
        column = -1 if measure == "success" else -2
        if self._floor is None:
            self._floor = [float(batch[:, -2].min()), float(batch[:, -1].min())]
        dims = len(self.space)

        def scored(rows: np.ndarray) -> np.ndarray:
            """Rows with their performance under this update's measure appended."""
            return np.concatenate([rows, rows[:, column, None]], axis=1)

        successes, failed, self._buffer_reached = update_successes(
            scored(self._successes),
            scored(batch),
            dims,
            math.inf if bar is None else bar,
            self._buffer_reached,
            self.params.particles,
            functools.partial(self._target_samples, index),
            self._scale,
        )
        self._successes = successes[:, :-1]
        if self._threshold_reached:
            self._failures = np.concatenate([self._failures, batch[failed]])[-self.failures_kept :]
        if self.params.estimate == "recent":
            self._window = np.concatenate([self._window, batch])[-self.params.recent_results :]
        keep = [*range(dims), dims + 2 + column]
        return FitInputs(
            self._particles,
            self._successes[:, keep],
            self._failures[:, keep],
            measure,
            bar,
            self._floor[1 if measure == "success" else 0],
            self._buffer_reached,
            self._threshold_reached,
            self._window[:, keep] if self.params.estimate == "recent" else None,
        )

    def _target_samples(self, index: int) -> np.ndarray:
        rng = np.random.default_rng([indexed_seed(self.seed, FIT_STREAM, index), 1])
        return self._target.samples(rng.random, self.params.particles)

    def refit_job(self, index: int) -> FitJob:
        """Update ``index`` starts from the inputs fixed when it fell due (kept until a later update
        is installed or ``MAX_PENDING_FITS`` later ones fall due)."""
        if not 0 <= index < self.fits_requested:
            raise ValueError(f"fit {index} has not fallen due ({self.fits_requested} have)")
        if index not in self._pending:
            raise ValueError(f"fit {index} was superseded: a later fit is installed or due")
        run = functools.partial(
            move_particles,
            index,
            self._pending[index],
            self.radius,
            self.params.candidates,
            self._target,
            self._scale,
            self.params.below_bar == "walk",
            indexed_seed(self.seed, FIT_STREAM, index),
        )
        return FitJob(index=index, run=run)

    def install(self, fitted: ParticleFit) -> None:
        if not isinstance(fitted, ParticleFit):
            raise TypeError(f"expected the ParticleFit returned by a FitJob, got {type(fitted).__name__}")
        if self._fit is not None and fitted.index <= self._fit.index:
            raise ValueError(f"fit {fitted.index} is stale: fit {self._fit.index} is installed")
        inputs = self._pending.get(fitted.index)
        before = self._particles if inputs is None else inputs.particles
        self._adopt(fitted)
        reasons = ", ".join(
            f"{int(np.sum(fitted.why == code))} {words}" for code, words in enumerate(WHY) if np.any(fitted.why == code)
        )
        bar = "none yet" if fitted.bar is None else f"{fitted.bar:g}"
        self._moves.append(
            {
                "at_results": (fitted.index + 1) * self.params.update_every,
                "fit": fitted.index,
                "from": self._mean_task(before),
                "to": self._mean_task(fitted.particles),
                "longest_move": float(np.linalg.norm((fitted.particles - before) * self._scale, axis=-1).max()),
                "why": f"{reasons} (estimated {fitted.measure} bar {bar})",
            }
        )

    def _adopt(self, fitted: ParticleFit) -> None:
        self._fit = fitted
        self._particles = fitted.particles
        self._threshold_reached = self._threshold_reached or fitted.threshold_reached
        self.fits_installed += 1
        for done in [index for index in self._pending if index <= fitted.index]:
            del self._pending[done]

    def export_fit(self, fitted: ParticleFit) -> dict[str, Any]:
        return {
            "index": fitted.index,
            "particles": fitted.particles.tolist(),
            "values": fitted.values.tolist(),
            "why": fitted.why.tolist(),
            "measure": fitted.measure,
            "bar": fitted.bar,
            "threshold_reached": fitted.threshold_reached,
        }

    def import_fit(self, data: Mapping[str, Any]) -> ParticleFit:
        shape = (self.params.particles, len(self.space))
        particles = np.array(data["particles"], dtype=np.float64)
        values = np.array(data["values"], dtype=np.float64)
        why = np.array(data["why"], dtype=np.int64)
        if particles.shape != shape or values.shape != shape[:1] or why.shape != shape[:1]:
            raise ValueError(
                f"a fit of {shape[0]} particles in {shape[1]} dimensions needs particles of shape {shape} and "
                f"{shape[0]} values and reasons, got {particles.shape}, {values.shape} and {why.shape}"
            )
        bar = None if data["bar"] is None else float(data["bar"])
        return ParticleFit(
            int(data["index"]), particles, values, why, str(data["measure"]), bar, bool(data["threshold_reached"])
        )

    def _history_rows(self) -> RowLog:
        """One row per result: its task in unit coordinates, its reward and its success (1, 0, or
        -1 when not reported)."""
        return self._log

    def _export(self) -> dict[str, Any]:
        return {
            "history_rows": self._log.size,
            "history_from": self._log.needed_from,
            "model": None if self._fit is None else self.export_fit(self._fit),
            "pending": [[index, inputs.export()] for index, inputs in self._pending.items()],
            **({"window": self._window.tolist()} if self.params.estimate == "recent" else {}),
            **super()._export(),
        }

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        dims = len(self.space)
        # right after an update no row is needed, and an empty history may come without columns
        rows = history if history.size else np.empty((0, dims + 2))
        self._log.load(rows, int(state["history_from"]), int(state["history_rows"]))
        if state["model"] is not None:
            self._adopt(self.import_fit(state["model"]))
        super()._import(state, history)  # after the model, whose install moves the counters and flags
        self._pending = {int(index): FitInputs.load(inputs, dims) for index, inputs in state["pending"]}
        window = state["window"] if self.params.estimate == "recent" else []
        self._window = np.array(window, dtype=np.float64).reshape(-1, dims + 2)

    def _target_view(self) -> Task | dict[str, list[float]] | None:
        """The target in task units: none for ``uniform``, a task for ``hardest``, a range per
        parameter for ``box``."""
        if self.params.target == "uniform":
            return None
        low, high = (
            self.space.from_array(self.space.from_unit(corner)) for corner in (self._target.low, self._target.high)
        )
        if self.params.target == "hardest":
            return low
        return {name: [low[name], high[name]] for name in self.space.names}

    def _mean_task(self, particles: np.ndarray) -> Task:
        return self.space.from_array(self.space.from_unit(particles.mean(axis=0)))

    def _describe(self) -> dict[str, Any]:
        fit = self._fit
        every = self.params.update_every
        measure, bar = self._bar()
        return {
            "particles": [self.space.from_array(row) for row in self.space.from_unit(self._particles)],
            "particle_values": [] if fit is None else fit.values.tolist(),
            "measure": None if fit is None else fit.measure,
            "bar": None if fit is None else fit.bar,
            "next_bar": {
                "measure": measure,
                "bar": bar,
                "source": "success_delta"
                if measure == "success"
                else ("delta" if self.params.delta is not None else "learned from the returns seen"),
            },
            "success_buffer": len(self._successes),
            "failures_kept": len(self._failures),
            **({"recent_window": len(self._window)} if self.params.estimate == "recent" else {}),
            "threshold_reached": self._threshold_reached,
            "target": self._target_view(),
            "fits": self.fits_installed,
            "fits_requested": self.fits_requested,
            "last_fit_index": None if fit is None else fit.index,
            "next_fit_at_results": (self.results_seen // every + 1) * every,
            "moves": list(self._moves),
        }
