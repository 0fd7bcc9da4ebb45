"""CURROT (Klink et al. 2022, "Curriculum Reinforcement Learning via Constrained Optimal Transport").

The curriculum is a cloud of task particles; each task is a particle picked at random plus a little
uniform noise. Every ``update_every`` results the particles move toward a target distribution (by
default samples of the uniform distribution over the box; optionally the space's hardest task)
under two constraints: no particle moves further than ``max_move`` (a share of the box's diagonal),
and a particle the student is estimated to master only moves to places where the estimated
performance stays at or above the bar. The estimate is a Nadaraya-Watson (Gaussian kernel)
regression over the last ``buffer_size`` results, with a length scale of 0.3 times the move radius,
as in the reference.

One update, following the reference code (github.com/psclklnk/currot, ``CurrOT``,
``WassersteinSuccessBuffer`` and ``SamplingWassersteinInterpolation``): particles are matched one to
one to target samples by an optimal-transport assignment (``scipy.optimize.linear_sum_assignment``
on squared distances). A particle estimated at or above the bar tries ``candidates`` points in the
half ball facing its target sample (radius: the move limit, or the distance to the target when that
is less) and goes to the one closest to its target among those estimated at or above the bar,
staying put when none is. A particle below the bar heads for a recent task that reached the bar,
matched by the same kind of assignment; while no recent task has, for one that did better than
the window's median (the reference's buffer keeps the better half until the bar is reached).

Where ours differs from the reference, and why:
- distances are measured in the box rescaled to [0, 1] per dimension (the reference uses raw
  units, where a parameter spanning 0.04 next to one spanning 0.89 barely counts);
- the estimate is fitted to a sliding window of recent results, averaging the 32 nearest at each
  point, instead of the reference's buffer of successful (or, before the bar is reached, best)
  tasks plus recent failures; the movement uses an exact assignment instead of sliced Wasserstein;
- a particle below the bar walks at most ``max_move`` toward its matched task instead of being
  replaced by it, so every particle's move is bounded;
- the measure: when every result in the window reports ``success``, the estimate is a success
  rate held to ``success_delta``; otherwise it is the return held to ``delta``. On KUKA a grasp is
  worth about +10 and a failed episode ends around -2..+2, so the defaults, a return of 5 or a
  success rate of 0.5, both mean "succeeds about half the time". Other reward scales need their
  own ``delta`` (rewards in [0, 1]: 0.5).

When it helps: a student that learns nothing from the hardest tasks but can be led there through
tasks it already half masters, in spaces where the way to the target is not a straight line;
unlike SPDL's Gaussian, the particle cloud can take any shape.

When it fails: particles only move toward tasks that did better than others, and tasks stay within
``noise`` of a particle. If no particle starts where the student earns anything, every result is
the same and nothing ever moves. On the ALP-GMM paper's toy, where only 1% of the space pays at
first, 200 uniform particles miss it with probability 0.99^200 (13%): one seed in five mastered
nothing (BENCHMARKS.md). Start near the easiest task (``start`` = easiest) when the student's
first successes are known to lie there.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree
from scipy.special import ndtri

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.draws import FIT_STREAM, TASK_STREAM, indexed_seed, indexed_uniforms
from teacher_service.teachers.params import FiniteFloat, TeacherParams
from teacher_service.teachers.row_log import RowLog

MAX_PARTICLES = 500
MAX_BUFFER = 2000
MAX_CANDIDATES = 64
"""Together these bound one update: at most 500 x 65 points estimated from their nearest among
2,000 results, and assignments of at most 500 particles to at most 2,000 tasks."""

LENGTHSCALE_SHARE = 0.3
"""The performance model's kernel length scale as a share of the move radius (the reference's choice)."""

NEIGHBOURS = 32
"""Results the estimate at a point averages over, the nearest (the reference also limits them): at
this length scale farther ones weigh next to nothing, and an update takes about a third of the time."""

MAX_PENDING_FITS = 4
"""Due fits whose starting particles are kept for ``refit_job``; an older one is superseded."""

RECENT_MOVES = 100
"""Updates the state reports in ``moves``."""

UNKNOWN_SUCCESS = -1.0
"""The history's success column when a result did not say."""

TOWARD_TARGET, TOWARD_SUCCESS, TOWARD_BETTER, STAYING = 0, 1, 2, 3
WHY = ("toward the target", "toward a success", "toward the better half", "staying")
"""Per-particle reasons for a move, as stored in a fit (codes) and told in ``moves`` (words)."""


class CurrotParams(TeacherParams):
    particles: int = Field(default=200, ge=2, le=MAX_PARTICLES)
    """Task particles; tasks are drawn from them. The authors used 100 to 500."""
    update_every: int = Field(default=50, ge=1, le=10_000)
    """Results between two particle updates (the authors: 50 episodes)."""
    buffer_size: int = Field(default=400, ge=1, le=MAX_BUFFER)
    """Recent results the performance estimate of an update is fitted to."""
    max_move: float = Field(default=0.05, gt=0.0, le=1.0)
    """Longest move of a particle in one update, as a share of the diagonal of the box rescaled to
    [0, 1] per dimension. The authors' TeachMyAgent setting passes 5% of the diagonal as its epsilon,
    which the reference code applies as a bound on the squared move, so its moves can be longer."""
    delta: FiniteFloat = Field(default=5.0, ge=-1e9, le=1e9)
    """The bar on the estimated return. KUKA: a grasp is worth about +10 and a failure ends around
    -2..+2, so 5 means succeeding about half the time."""
    success_delta: float = Field(default=0.5, ge=0.0, le=1.0)
    """The bar on the estimated success rate, used instead of ``delta`` when every result in an
    update's window reports ``success``."""
    candidates: int = Field(default=32, ge=1, le=MAX_CANDIDATES)
    """Points tried in the ball around each particle per update (the authors: 100)."""
    noise: float = Field(default=0.001, ge=0.0, le=0.5)
    """Half-width of the uniform noise added to a particle to make a task, per dimension in units of
    the dimension's width (the authors: 0.001)."""
    target: Literal["uniform", "hardest"] = "uniform"
    """Where the particles head: samples of the uniform distribution over the box, or the space's
    hardest task."""
    start: Literal["uniform", "easiest"] = "uniform"
    """Where the particles start: uniform over the box (as in the authors' experiments), or near the
    space's easiest task."""
    start_spread: float = Field(default=0.1, ge=0.0, le=10.0)
    """With ``start`` = easiest: standard deviation of the particles around it, per dimension in
    units of the dimension's width, clipped to the box."""

    @model_validator(mode="after")
    def _consistent(self) -> CurrotParams:
        if self.buffer_size < self.update_every:
            raise ValueError(
                f"buffer_size ({self.buffer_size}) cannot be less than update_every ({self.update_every}): "
                "an update would ignore some of the results since the last one"
            )
        return self


@dataclass(frozen=True)
class ParticleFit:
    """The output of one update: the new particles (unit coordinates), the estimate at each, and
    why each moved (``TOWARD_TARGET``, ``TOWARD_SUCCESS``, ``TOWARD_BETTER`` or ``STAYING``)."""

    index: int
    particles: np.ndarray
    values: np.ndarray
    why: np.ndarray
    measure: str
    bar: float


def squared_distances(points: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances, shape (len(points), len(others))."""
    squared = (
        np.einsum("ij,ij->i", points, points)[:, None]
        + np.einsum("ij,ij->i", others, others)[None, :]
        - 2.0 * points @ others.T
    )
    clipped: np.ndarray = np.maximum(squared, 0.0)
    return clipped


def estimate_performance(
    tasks: np.ndarray, performance: np.ndarray, lengthscale: float, points: np.ndarray
) -> np.ndarray:
    """Nadaraya-Watson estimate at ``points`` (n, d) from results at ``tasks`` (b, d): a Gaussian-
    kernel weighted mean over the ``NEIGHBOURS`` nearest results, normalised per point, so far
    from every result it is the nearest one's."""
    count = min(NEIGHBOURS, len(tasks))
    distances, nearest = (np.reshape(values, (len(points), count)) for values in cKDTree(tasks).query(points, k=count))
    logits = -(distances**2) / (2.0 * lengthscale**2)
    weights = np.exp(logits - logits.max(axis=1, keepdims=True))
    estimates: np.ndarray = np.einsum("nk,nk->n", weights, performance[nearest]) / weights.sum(axis=1)
    return estimates


def _assign(sources: np.ndarray, destinations: np.ndarray) -> np.ndarray:
    """For each source, the destination an optimal-transport assignment on squared distances gives
    it; destinations are repeated when there are fewer of them than sources."""
    repeats = -(-len(sources) // len(destinations))
    pool = np.tile(destinations, (repeats, 1))
    rows, columns = linear_sum_assignment(squared_distances(sources, pool))
    assigned = np.empty_like(sources)
    assigned[rows] = pool[columns]
    return assigned


def _ball(
    rng: np.random.Generator, centres: np.ndarray, toward: np.ndarray, radii: np.ndarray, count: int
) -> np.ndarray:
    """``count`` points uniform in the half ball of radius ``radii[i]`` around each centre that faces
    ``toward[i]`` (points behind are mirrored in front), shape (n, count, d), clipped to the unit box."""
    n, dims = centres.shape
    directions = rng.standard_normal((n, count, dims))
    directions /= np.maximum(np.linalg.norm(directions, axis=-1, keepdims=True), 1e-300)
    offsets = directions * rng.random((n, count, 1)) ** (1.0 / dims)
    heading = toward - centres
    heading /= np.maximum(np.linalg.norm(heading, axis=-1, keepdims=True), 1e-300)
    along = np.einsum("nkd,nd->nk", offsets, heading)
    offsets -= 2.0 * np.minimum(along, 0.0)[..., None] * heading[:, None, :]
    points: np.ndarray = np.clip(centres[:, None, :] + radii[:, None, None] * offsets, 0.0, 1.0)
    return points


def move_particles(
    index: int,
    particles: np.ndarray,
    tasks: np.ndarray,
    performance: np.ndarray,
    measure: str,
    bar: float,
    radius: float,
    candidates: int,
    target: np.ndarray | None,
    random_state: int,
) -> ParticleFit:
    """One CURROT update in unit coordinates (see the module docstring). ``target`` is a point, or
    ``None`` for samples of the uniform distribution; ``radius`` bounds every particle's move."""
    rng = np.random.Generator(np.random.PCG64(random_state))
    n, dims = particles.shape
    estimate = functools.partial(estimate_performance, tasks, performance, LENGTHSCALE_SHARE * radius)
    here = estimate(particles)
    samples = rng.random((n, dims)) if target is None else np.tile(target, (n, 1))
    goals = _assign(particles, samples)
    moved = particles.copy()
    why = np.full(n, STAYING, dtype=np.int64)

    above = np.flatnonzero(here >= bar)
    if len(above):
        start, goal = particles[above], goals[above]
        radii = np.minimum(radius, np.linalg.norm(goal - start, axis=-1))
        ball = np.concatenate([start[:, None, :], _ball(rng, start, goal, radii, candidates)], axis=1)
        ball_estimates = estimate(ball.reshape(-1, dims)).reshape(len(above), candidates + 1)
        ball_estimates[:, 0] = here[above]  # staying put is always allowed, whatever the batching
        to_goal = np.linalg.norm(ball - goal[:, None, :], axis=-1)
        closest_allowed = np.argmin(np.where(ball_estimates >= bar, to_goal, np.inf), axis=1)
        moved[above] = ball[np.arange(len(above)), closest_allowed]
        why[above] = TOWARD_TARGET

    below = np.flatnonzero(here < bar)
    reached = performance >= bar
    if np.any(reached):
        better, code = tasks[reached], TOWARD_SUCCESS
    else:
        better, code = tasks[performance > np.median(performance)], TOWARD_BETTER
    if len(below) and len(better):
        heading = _assign(particles[below], better) - particles[below]
        length = np.linalg.norm(heading, axis=-1, keepdims=True)
        moved[below] = particles[below] + heading * np.minimum(1.0, radius / np.maximum(length, 1e-300))
        why[below] = code
    return ParticleFit(index, moved, estimate(moved), why, measure, bar)


class CurrotTeacher(Teacher):
    """Task particles moved toward a target by constrained optimal transport (see the module docstring)."""

    kind = "currot"
    Params = CurrotParams
    params: CurrotParams

    def __init__(self, space: TaskSpace, seed: int, params: CurrotParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        dims, count = len(space), self.params.particles
        self._target: np.ndarray | None = None
        if self.params.target == "hardest":
            self._target = self._anchor("target", space.hardest)
        start = indexed_uniforms(seed, FIT_STREAM, 0, count, dims)
        if self.params.start == "easiest":
            easiest = self._anchor("start", space.easiest)
            start = np.clip(easiest + self.params.start_spread * ndtri(start + 2.0**-54), 0.0, 1.0)
        self._particles = start
        self._fit: ParticleFit | None = None
        self._log = RowLog(dims + 2, 2 * self.params.buffer_size)
        self.fits_requested = 0
        self.fits_installed = 0
        self._starting_points: dict[int, np.ndarray] = {}
        self._moves: deque[dict[str, Any]] = deque(maxlen=RECENT_MOVES)

    def _anchor(self, name: str, anchor: Callable[[], Task]) -> np.ndarray:
        try:
            unit: np.ndarray = self.space.to_unit(self.space.to_array(anchor()))
        except ValueError as error:
            raise ValueError(f"{name}: {error}") from None
        return unit

    @property
    def radius(self) -> float:
        """The longest move in unit coordinates: ``max_move`` times the unit box's diagonal."""
        return self.params.max_move * math.sqrt(len(self.space))

    def _draw(self, first_index: int, count: int) -> list[Task]:
        dims, particles = len(self.space), self._particles
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, 1 + dims)
        picked = np.minimum((uniforms[:, 0] * len(particles)).astype(np.int64), len(particles) - 1)
        units = np.clip(particles[picked] + self.params.noise * (2.0 * uniforms[:, 1:] - 1.0), 0.0, 1.0)
        return [self.space.from_array(row) for row in self.space.from_unit(units)]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        success = UNKNOWN_SUCCESS if result.success is None else float(result.success)
        unit = self.space.to_unit(self.space.to_array(result.task))
        self._log.append(np.concatenate([unit, (result.reward, success)]))
        if self.results_seen % self.params.update_every:
            return None
        self.fits_requested += 1
        index = self.fits_requested - 1
        self._starting_points[index] = self._particles
        for stale in sorted(self._starting_points)[:-MAX_PENDING_FITS]:
            del self._starting_points[stale]
        self._log.needed_from = self._window_start(min(self._starting_points))
        return self.refit_job(index)

    def _window_start(self, index: int) -> int:
        """The first of the results that update ``index`` sees."""
        return max(0, (index + 1) * self.params.update_every - self.params.buffer_size)

    def refit_job(self, index: int) -> FitJob:
        """Update ``index`` starts from the particles installed when it fell due (kept until a
        later update is installed) and sees the ``buffer_size`` results before it."""
        if not 0 <= index < self.fits_requested:
            raise ValueError(f"fit {index} has not fallen due ({self.fits_requested} have)")
        if index not in self._starting_points:
            raise ValueError(f"fit {index} was superseded: a later fit is installed or due")
        window = self._log.view(self._window_start(index), (index + 1) * self.params.update_every)
        if np.all(window[:, -1] != UNKNOWN_SUCCESS):
            measure, performance, bar = "success", window[:, -1].copy(), self.params.success_delta
        else:
            measure, performance, bar = "return", window[:, -2].copy(), self.params.delta
        run = functools.partial(
            move_particles,
            index,
            self._starting_points[index],
            window[:, :-2].copy(),
            performance,
            measure,
            bar,
            self.radius,
            self.params.candidates,
            self._target,
            indexed_seed(self.seed, FIT_STREAM, index),
        )
        return FitJob(index=index, run=run)

    def install(self, fitted: ParticleFit) -> None:
        if not isinstance(fitted, ParticleFit):
            raise TypeError(f"expected the ParticleFit returned by a FitJob, got {type(fitted).__name__}")
        if self._fit is not None and fitted.index <= self._fit.index:
            raise ValueError(f"fit {fitted.index} is stale: fit {self._fit.index} is installed")
        before = self._starting_points.get(fitted.index, self._particles)
        self._adopt(fitted)
        reasons = ", ".join(
            f"{int(np.sum(fitted.why == code))} {words}" for code, words in enumerate(WHY) if np.any(fitted.why == code)
        )
        self._moves.append(
            {
                "at_results": (fitted.index + 1) * self.params.update_every,
                "fit": fitted.index,
                "from": self._mean_task(before),
                "to": self._mean_task(fitted.particles),
                "longest_move": float(np.linalg.norm(fitted.particles - before, axis=-1).max()),
                "why": f"{reasons} (estimated {fitted.measure} bar {fitted.bar:g})",
            }
        )

    def _adopt(self, fitted: ParticleFit) -> None:
        self._fit = fitted
        self._particles = fitted.particles
        self.fits_installed += 1
        for done in [index for index in self._starting_points if index <= fitted.index]:
            del self._starting_points[done]

    def export_fit(self, fitted: ParticleFit) -> dict[str, Any]:
        return {
            "index": fitted.index,
            "particles": fitted.particles.tolist(),
            "values": fitted.values.tolist(),
            "why": fitted.why.tolist(),
            "measure": fitted.measure,
            "bar": fitted.bar,
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
        return ParticleFit(int(data["index"]), particles, values, why, str(data["measure"]), float(data["bar"]))

    def _history_rows(self) -> RowLog:
        """One row per result: its task in unit coordinates, its reward and its success (1, 0, or
        -1 when not reported)."""
        return self._log

    def _export(self) -> dict[str, Any]:
        return {
            "history_rows": self._log.size,
            "history_from": self._log.needed_from,
            "fits_requested": self.fits_requested,
            "fits_installed": self.fits_installed,
            "model": None if self._fit is None else self.export_fit(self._fit),
            "starting_points": [[index, points.tolist()] for index, points in self._starting_points.items()],
            "moves": list(self._moves),
        }

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        first = int(state.get("history_from", 0))
        self._log.load(history, first, int(state["history_rows"]))
        if state["model"] is not None:
            self._adopt(self.import_fit(state["model"]))
        self.fits_requested = int(state["fits_requested"])
        self.fits_installed = int(state["fits_installed"])
        self._starting_points = {
            int(index): np.array(points, dtype=np.float64) for index, points in state["starting_points"]
        }
        self._moves.extend(state["moves"])

    def _mean_task(self, particles: np.ndarray) -> Task:
        return self.space.from_array(self.space.from_unit(particles.mean(axis=0)))

    def _describe(self) -> dict[str, Any]:
        fit = self._fit
        every = self.params.update_every
        return {
            "particles": [self.space.from_array(row) for row in self.space.from_unit(self._particles)],
            "particle_values": [] if fit is None else fit.values.tolist(),
            "measure": None if fit is None else fit.measure,
            "bar": None if fit is None else fit.bar,
            "target": None if self._target is None else self.space.from_array(self.space.from_unit(self._target)),
            "fits": self.fits_installed,
            "fits_requested": self.fits_requested,
            "last_fit_index": None if fit is None else fit.index,
            "next_fit_at_results": (self.results_seen // every + 1) * every,
            "moves": list(self._moves),
        }
