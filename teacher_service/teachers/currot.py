"""CURROT (Klink et al. 2022, "Curriculum Reinforcement Learning via Constrained Optimal Transport").

The curriculum is a cloud of task particles; each task is a particle picked at random plus a little
uniform noise. Every ``update_every`` results the particles move toward a target distribution (by
default samples of the uniform distribution over the box; optionally the space's hardest task, or
samples of the uniform distribution over a smaller box given in ``target_box``), each at most
``max_move`` per update, and a particle the student is estimated to master only to places where
the estimated performance stays at or above the bar.

One update follows the authors' main branch (github.com/psclklnk/currot: ``CurrOT``,
``WassersteinSuccessBuffer``, ``SamplingWassersteinInterpolation``):

1. A lasting success buffer of at most ``particles`` tasks takes the new results. Until its median
   performance exceeds the bar it keeps the better half of everything seen (a result joins when it
   does at least as well as the buffer's median); after that, results at or above the bar replace
   those below it, and once all are above it, an optimal-transport assignment to target samples
   decides which successes stay. Results that do not join are failures.
2. Once the particles' mean estimate has first reached the bar, the last ``buffer_size`` failures
   are kept beside the success buffer; the performance estimate is a Nadaraya-Watson (Gaussian
   kernel) regression over both, with a length scale of 0.3 times the move radius.
3. Particles estimated below the bar are replaced by samples of the success buffer with Gaussian
   noise (an optimal-transport assignment picks which): the noise is a quarter of the box per
   dimension for a buffered task at the lowest performance of the first results and shrinks to
   nothing at the bar, so while the student earns nothing anywhere the particles keep exploring the
   whole box instead of standing still. Before the buffer's median reaches the bar, samples come
   from its better half, favouring the better ones.
4. Every particle is matched to a target sample by an optimal-transport assignment and tries
   ``candidates`` points in a ball around it (radius: the move limit, or the distance to its target
   when less; the half ball facing the target for particles at or above the bar, the full ball for
   those that are not). It goes to the candidate closest to its target among those estimated at or
   above the bar, or when none is, to the one with the best estimate.

Where ours departs from the authors', and what it costs or gains:
- ``distances`` = ``unit`` (default): distances, the move radius, the noise and the kernel length
  scale are measured in the box rescaled to [0, 1] per dimension; the authors use raw units
  (``raw``), where a parameter spanning 0.04 beside one spanning 0.89 barely counts. The two are the
  same on a unit box, so the toy cannot tell them apart; on KUKA's hard family the difference is
  not measured yet (raw units would move the narrow parameters hardly at all).
- ``below_bar`` = ``jump`` (default, the authors'): a particle below the bar jumps to its success
  sample. ``walk`` moves it at most ``max_move`` toward it, so every move is bounded; on the ALP-GMM
  paper's toy walking costs a little from the easiest corner, and the noisy resampling, not the
  jump, is what rescues a uniform start (docs/results/parity.md).
- ``max_move`` bounds the move; the authors' ``epsilon`` bounds its square (TeachMyAgent passes 5%
  of the diagonal, a radius of 27% of a unit square's diagonal); give the radius you want.
- The movement's assignment is exact (``scipy.optimize.linear_sum_assignment``) where the authors
  use sliced Wasserstein; the estimate averages the 32 nearest buffered results at each point.
- ``estimate`` = recent (not the default): the estimate is fitted to the last ``recent_results``
  results instead of the success buffer and the kept failures. The lasting buffer keeps successes
  from before a student's success rate fell, and on KukaGraspHard-v1 it held the estimate near the
  bar at the hardest point while the student rarely succeeded there (docs/results/bakeoff-hard.md).
  The buffer still supplies the replacement samples, but a particle below the bar takes only
  a sample estimated at or above it: when fewer samples are, the assignment gives them to the
  particles nearest them and the rest stay, to move to the best candidate of their full ball.
- Until the particles' estimate first reaches the bar, failures are not kept (as the authors'), but
  the decision is taken from the update installed when a new one falls due: a service that installs
  updates late (the replay never does) can keep its first failures one update later.

The measure: while every result so far reported ``success``, the estimate is a success rate held
to ``success_delta``; otherwise it is the return held to ``delta``. Without ``delta`` (the default)
the return bar is ``success_delta`` of the way from the lowest to the highest return seen so far,
and no result meets it until two different returns were seen, so the defaults work on any reward
scale. ``train`` passes 5.0 for KUKA (a grasp is worth about +10, a failure ends around -2..+2).

On the ALP-GMM paper's toy this masters as much of the space as the authors' code, seed for seed
within noise (docs/results/parity.md). There only the corner cube pays at first, and a uniform cloud
can miss it: the noisy resampling above is what finds it.

When it helps: a student that learns nothing from the hardest tasks but can be led there through
tasks it already half masters, in spaces where the way to the target is not a straight line;
unlike SPDL's Gaussian, the particle cloud can take any shape.
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
from teacher_service.teachers.params import FiniteFloat, TaskBox, TeacherParams, box_in_space, check_target_box
from teacher_service.teachers.performance import UNKNOWN_SUCCESS, ReturnScale
from teacher_service.teachers.row_log import RowLog

MAX_PARTICLES = 500
MAX_BUFFER = 2000
MAX_CANDIDATES = 128
"""Together these bound one update: at most 500 x 128 points estimated from their nearest among
2,500 buffered results (or 2,000 recent ones), and assignments of at most 500 particles to at most
2,500 tasks."""

DEFAULT_RECENT = 400
"""Results the estimate is fitted to with ``estimate`` = recent, unless ``recent_results`` says."""

LENGTHSCALE_SHARE = 0.3
"""The performance model's kernel length scale as a share of the move radius (the authors' choice)."""

NEIGHBOURS = 32
"""Buffered results the estimate at a point averages over, the nearest (the authors' compiled
estimator also limits them): at this length scale farther ones weigh next to nothing."""

SEARCH_SHARE = 0.25
"""The resampling noise's largest standard deviation, as a share of the box per dimension (the authors')."""

MIN_NOISE_SHARE = 0.005
"""The resampling noise's smallest standard deviation: this share of the squared move radius (the
authors' ``0.005 * epsilon``, their epsilon being the squared radius)."""

RESAMPLE_TRIES = 10
"""Redraws of the resampling noise for a sample that fell outside the box, before it is clipped."""

MAX_PENDING_FITS = 4
"""Due fits whose inputs are kept for ``refit_job``; an older one is superseded."""

RECENT_MOVES = 100
"""Updates the state reports in ``moves``."""

TOWARD_TARGET, TO_BEST, REPLACED_TOWARD_TARGET, REPLACED_TO_BEST = 0, 1, 2, 3
WHY = (
    "toward the target",
    "to the best estimate nearby",
    "from the success buffer, then toward the target",
    "from the success buffer, then to the best estimate nearby",
)
"""Per-particle reasons for a move, as stored in a fit (codes) and told in ``moves`` (words)."""


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
    or walks at most ``max_move`` toward it (cost measured on the toy: see the module docstring)."""
    distances: Literal["unit", "raw"] = "unit"
    """Distances measured in the box rescaled to [0, 1] per dimension, or in the task's own units
    (the authors')."""
    estimate: Literal["buffers", "recent"] = "buffers"
    """What the performance estimate is fitted to. "buffers": the success buffer and the recent
    failures (the authors'). "recent": the last ``recent_results`` results only, successes and
    failures alike, as they came, so a student whose success rate at a place is below the bar is
    estimated below it there, whatever successes the buffer still holds from before; a particle
    below the bar is then replaced only by a sample estimated at or above it (see the module
    docstring)."""
    recent_results: int = Field(default=DEFAULT_RECENT, ge=1, le=MAX_BUFFER)
    """With ``estimate`` = recent (and only then): how many of the latest results the estimate is
    fitted to."""

    @model_validator(mode="after")
    def _consistent(self) -> CurrotParams:
        check_target_box(self.target, self.target_box)
        if self.estimate != "recent" and self.recent_results != DEFAULT_RECENT:
            raise ValueError(f"recent_results is read only with estimate 'recent', not {self.estimate!r}")
        return self


@dataclass(frozen=True)
class TargetBox:
    """Where the particles head, in unit coordinates: samples uniform in [``low``, ``high``]; the
    whole box for ``uniform``, one point for ``hardest``."""

    low: np.ndarray
    high: np.ndarray

    def samples(self, uniforms: Callable[[tuple[int, int]], np.ndarray], count: int) -> np.ndarray:
        """``count`` samples from ``uniforms`` (shape to uniforms on [0, 1)). A point takes no draws and
        the whole box takes them unchanged, so both targets draw as they did before boxes."""
        if np.array_equal(self.low, self.high):
            return np.tile(self.low, (count, 1))
        drawn: np.ndarray = self.low + (self.high - self.low) * uniforms((count, len(self.low)))
        return drawn


@dataclass(frozen=True)
class FitInputs:
    """What one update starts from, fixed when it falls due: the particles (unit coordinates), the
    success buffer and the kept failures (rows of unit task and performance), the bar (``None``:
    no bar yet), the lowest performance of the first results, and the two flags of the authors'
    code: the buffer's median has exceeded the bar; the particles' estimate has reached it. With
    ``estimate`` = recent, ``window`` holds the latest results (rows as the buffers') the estimate
    is fitted to instead of the buffers; ``None``: the buffers'."""

    particles: np.ndarray
    successes: np.ndarray
    failures: np.ndarray
    measure: str
    bar: float | None
    floor: float
    buffer_reached: bool
    threshold_reached: bool
    window: np.ndarray | None = None

    def export(self) -> dict[str, Any]:
        return {
            "particles": self.particles.tolist(),
            "successes": self.successes.tolist(),
            "failures": self.failures.tolist(),
            "measure": self.measure,
            "bar": self.bar,
            "floor": self.floor,
            "buffer_reached": self.buffer_reached,
            "threshold_reached": self.threshold_reached,
            **({} if self.window is None else {"window": self.window.tolist()}),
        }

    @classmethod
    def load(cls, data: Mapping[str, Any], dims: int) -> FitInputs:
        def rows(name: str, width: int) -> np.ndarray:
            return np.array(data[name], dtype=np.float64).reshape(-1, width)

        return cls(
            rows("particles", dims),
            rows("successes", dims + 1),
            rows("failures", dims + 1),
            str(data["measure"]),
            None if data["bar"] is None else float(data["bar"]),
            float(data["floor"]),
            bool(data["buffer_reached"]),
            bool(data["threshold_reached"]),
            rows("window", dims + 1) if "window" in data else None,
        )


@dataclass(frozen=True)
class ParticleFit:
    """The output of one update: the new particles (unit coordinates), the estimate at each, why
    each moved (codes of ``WHY``), and whether the particles' estimate has reached the bar."""

    index: int
    particles: np.ndarray
    values: np.ndarray
    why: np.ndarray
    measure: str
    bar: float | None
    threshold_reached: bool


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


def update_successes(
    buffer: np.ndarray,
    batch: np.ndarray,
    dims: int,
    bar: float,
    reached: bool,
    capacity: int,
    targets: Callable[[], np.ndarray],
    scale: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, bool]:
    """The authors' ``WassersteinSuccessBuffer.update`` on rows that start with a unit task of
    ``dims`` coordinates and end with a performance: the new buffer, which of ``batch`` failed to
    join it, and whether its median has exceeded ``bar``. ``targets()`` draws target samples (unit
    coordinates), needed only once the buffer is full of successes; ``scale`` turns unit
    coordinates into the units distances are measured in."""
    performance, new = buffer[:, -1], batch[:, -1]
    if not reached:
        buffer = buffer[np.argsort(performance, kind="stable")]
        middle = len(buffer) // 2
        median = buffer[middle, -1] if len(buffer) else -math.inf
        joins = new >= median
        joined = int(joins.sum())
        merged = np.concatenate([batch[joins], buffer[min(middle + 1, joined) :]])
        kept = np.argsort(merged[:, -1], kind="stable")[-capacity:]
        failed = ~joins
        failed[joins] = ~np.isin(np.arange(joined), kept)
        return merged[kept], failed, bool(len(buffer) and median > bar)
    joins = new >= bar
    joined = int(joins.sum())
    if not joined:
        return buffer, ~joins, True
    below = performance < bar
    if not below.any() and len(buffer) >= capacity:
        extended = np.concatenate([buffer, batch[joins]])
        rows, _ = linear_sum_assignment(squared_distances(extended[:, :dims] * scale, targets() * scale))
        joins[joins] = np.isin(np.arange(joined) + len(buffer), rows)
        return extended[np.sort(rows)], ~joins, True
    if joined < below.sum():
        below = np.zeros(len(buffer), dtype=bool)
        below[np.argpartition(performance, joined)[:joined]] = True
    return np.concatenate([batch[joins], buffer[~below]])[:capacity], ~joins, True


def resample_successes(
    rng: np.random.Generator, inputs: FitInputs, count: int, scale: np.ndarray, min_std: float
) -> np.ndarray:
    """The authors' ``read_update``: ``count`` samples of the success buffer with Gaussian noise
    whose spread grows from ``min_std`` at the bar to a quarter of the box at the lowest performance
    of the first results; until the buffer's median exceeds the bar, drawn from its better half in
    proportion to how much better than its median each did. Unit coordinates, in the box."""
    tasks, performance = inputs.successes[:, :-1], inputs.successes[:, -1]
    bar = math.inf if inputs.bar is None else inputs.bar
    if not math.isfinite(bar):
        shares = np.ones(len(performance))
    elif bar - inputs.floor <= 0.0:
        shares = (performance < bar).astype(np.float64)
    else:
        shares = np.clip(bar - performance, 0.0, None) / (bar - inputs.floor)
    stds = min_std / scale + shares[:, None] * SEARCH_SHARE
    if not inputs.buffer_reached:
        middle = len(performance) // 2
        weights = performance[middle:] - performance[middle - 1]
        total = weights.sum()
        probabilities = np.full(len(weights), 1.0 / len(weights)) if total == 0 else weights / total
        picks = middle + rng.choice(len(weights), count, p=probabilities)
    else:
        picks = np.concatenate([np.arange(len(tasks)), rng.choice(len(tasks), max(count - len(tasks), 0))])
    centres, spreads = tasks[picks], stds[picks]
    samples = centres + spreads * rng.standard_normal(centres.shape)
    for _ in range(RESAMPLE_TRIES):
        outside = np.any((samples < 0.0) | (samples > 1.0), axis=-1)
        if not outside.any():
            break
        samples[outside] = centres[outside] + spreads[outside] * rng.standard_normal(
            (int(outside.sum()), tasks.shape[1])
        )
    clipped: np.ndarray = np.clip(samples, 0.0, 1.0)
    return clipped


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
    rng: np.random.Generator,
    centres: np.ndarray,
    toward: np.ndarray,
    radii: np.ndarray,
    half: np.ndarray,
    count: int,
    box: np.ndarray,
) -> np.ndarray:
    """``count`` points uniform in the ball of radius ``radii[i]`` around each centre, or where
    ``half[i]`` the half ball facing ``toward[i]`` (points behind are mirrored in front), shape
    (n, count, d), clipped to the box [0, ``box``]."""
    n, dims = centres.shape
    directions = rng.standard_normal((n, count, dims))
    directions /= np.maximum(np.linalg.norm(directions, axis=-1, keepdims=True), 1e-300)
    offsets = directions * rng.random((n, count, 1)) ** (1.0 / dims)
    heading = toward - centres
    heading /= np.maximum(np.linalg.norm(heading, axis=-1, keepdims=True), 1e-300)
    along = np.einsum("nkd,nd->nk", offsets, heading)
    offsets -= 2.0 * (np.minimum(along, 0.0) * half[:, None])[..., None] * heading[:, None, :]
    points: np.ndarray = np.clip(centres[:, None, :] + radii[:, None, None] * offsets, 0.0, box)
    return points


def move_particles(
    index: int,
    inputs: FitInputs,
    radius: float,
    candidates: int,
    target: TargetBox,
    scale: np.ndarray,
    walk: bool,
    random_state: int,
) -> ParticleFit:
    """One CURROT update (see the module docstring). Geometry runs in unit coordinates times
    ``scale`` (ones, or the parameters' widths); ``radius`` is the longest move in those units;
    each particle heads for a sample of ``target``; ``walk`` bounds the move of a replaced particle
    too."""
    rng = np.random.Generator(np.random.PCG64(random_state))
    n, dims = inputs.particles.shape
    bar = math.inf if inputs.bar is None else inputs.bar
    known = np.concatenate([inputs.failures, inputs.successes]) if inputs.window is None else inputs.window
    estimate = functools.partial(estimate_performance, known[:, :-1] * scale, known[:, -1], LENGTHSCALE_SHARE * radius)
    particles = inputs.particles * scale
    here = estimate(particles)
    threshold_reached = inputs.threshold_reached or bool(here.mean() >= bar)

    reached = here >= bar
    replaced = ~reached
    if replaced.any():
        samples = resample_successes(rng, inputs, n, scale, MIN_NOISE_SHARE * radius**2) * scale
        valid = estimate(samples) >= bar
        if valid.sum() >= replaced.sum() or inputs.window is not None:
            samples, valid = samples[valid], valid[valid]
        # every particle below the bar is assigned a sample, unless (with a window) too few are valid
        assigned, picked = linear_sum_assignment(squared_distances(particles[replaced], samples))
        replaced[replaced] = np.isin(np.arange(replaced.sum()), assigned)
        if walk:
            heading = samples[picked] - particles[replaced]
            length = np.linalg.norm(heading, axis=-1, keepdims=True)
            particles[replaced] += heading * np.minimum(1.0, radius / np.maximum(length, 1e-300))
            reached[replaced] = estimate(particles[replaced]) >= bar
        else:
            particles[replaced] = samples[picked]
            reached[replaced] = valid[picked]

    goals = target.samples(rng.random, n) * scale
    goals = _assign(particles, goals)
    radii = np.minimum(radius, np.linalg.norm(goals - particles, axis=-1))
    ball = _ball(rng, particles, goals, radii, reached, candidates, scale)
    estimates = estimate(ball.reshape(-1, dims)).reshape(n, candidates)
    allowed = estimates >= bar
    to_goal = np.where(allowed, np.linalg.norm(ball - goals[:, None, :], axis=-1), np.inf)
    choice = np.where(allowed.any(axis=1), np.argmin(to_goal, axis=1), np.argmax(estimates, axis=1))
    every = np.arange(n)
    why = np.where(allowed.any(axis=1), TOWARD_TARGET, TO_BEST) + 2 * replaced
    return ParticleFit(
        index,
        ball[every, choice] / scale,
        estimates[every, choice],
        why.astype(np.int64),
        inputs.measure,
        inputs.bar,
        threshold_reached,
    )


class CurrotTeacher(Teacher):
    """Task particles moved toward a target by constrained optimal transport, kept where the student
    is estimated to reach the bar: a success rate of ``success_delta`` while results carry
    ``success``, else a return of ``delta``, or without it ``success_delta`` of the way through the
    returns seen (see the module docstring)."""

    kind = "currot"
    Params = CurrotParams
    params: CurrotParams

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
            "fits_requested": self.fits_requested,
            "fits_installed": self.fits_installed,
            "model": None if self._fit is None else self.export_fit(self._fit),
            "pending": [[index, inputs.export()] for index, inputs in self._pending.items()],
            "successes": self._successes.tolist(),
            "failures": self._failures.tolist(),
            **({"window": self._window.tolist()} if self.params.estimate == "recent" else {}),
            "buffer_reached": self._buffer_reached,
            "threshold_reached": self._threshold_reached,
            "floor": self._floor,
            "every_success": self._every_success,
            "returns_seen": self._returns.export(),
            "moves": list(self._moves),
        }

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        dims = len(self.space)
        # right after an update no row is needed, and an empty history may come without columns
        rows = history if history.size else np.empty((0, dims + 2))
        self._log.load(rows, int(state["history_from"]), int(state["history_rows"]))
        if state["model"] is not None:
            self._adopt(self.import_fit(state["model"]))
        self.fits_requested = int(state["fits_requested"])
        self.fits_installed = int(state["fits_installed"])
        self._pending = {int(index): FitInputs.load(inputs, dims) for index, inputs in state["pending"]}
        self._successes = np.array(state["successes"], dtype=np.float64).reshape(-1, dims + 2)
        self._failures = np.array(state["failures"], dtype=np.float64).reshape(-1, dims + 2)
        window = state["window"] if self.params.estimate == "recent" else []
        self._window = np.array(window, dtype=np.float64).reshape(-1, dims + 2)
        self._buffer_reached = bool(state["buffer_reached"])
        self._threshold_reached = bool(state["threshold_reached"])
        self._floor = None if state["floor"] is None else [float(value) for value in state["floor"]]
        self._every_success = bool(state["every_success"])
        self._returns = ReturnScale(state["returns_seen"])
        self._moves.extend(state["moves"])

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
