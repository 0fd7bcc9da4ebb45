"""CURROT's particle update (Klink et al. 2022, "Curriculum Reinforcement Learning via Constrained
Optimal Transport"), pure numpy and scipy: the teacher adapter that keeps the particles, counts
results and saves its state is ``teachers.currot``.

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
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

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

TOWARD_TARGET, TO_BEST, REPLACED_TOWARD_TARGET, REPLACED_TO_BEST = 0, 1, 2, 3
WHY = (
    "toward the target",
    "to the best estimate nearby",
    "from the success buffer, then toward the target",
    "from the success buffer, then to the best estimate nearby",
)
"""Per-particle reasons for a move, as stored in a fit (codes) and told in ``moves`` (words)."""


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
