"""SPDL, self-paced deep RL (Klink et al. 2020, "Self-Paced Deep Reinforcement Learning"), in the
constrained form of Klink et al. 2021 ("A Probabilistic Interpretation of Self-Paced Learning with
Applications to Reinforcement Learning").

Tasks come from one Gaussian with a diagonal covariance, held on tasks rescaled to [0, 1] per
parameter and truncated to the box when sampled. It starts on the easiest task with a small spread
and moves toward a target distribution: by default a narrow Gaussian on the space's hardest task,
or (``target="uniform"``) the uniform distribution over the box, stood in for by the Gaussian
with its mean and variances, or (``target="box"``) the same stand-in for the uniform distribution
over ``target_box``. Every ``update_every`` results the Gaussian is re-chosen:

- if the expected performance of the current Gaussian (the mean performance of those results,
  ``performance.py``) is at least ``zeta``, the new Gaussian is the one closest to the target in
  KL divergence whose expected performance, estimated by importance weighting those results,
  stays at least ``zeta`` and whose KL divergence from the current one is at most ``kl_limit``;
- otherwise, until the bar has been reached once, it is the one with the highest estimated
  expected performance within the same KL limit, which moves it toward the tasks the student
  manages; after that (``below_bar="stay"``, the authors' rule) it is the step toward the target
  that brings the estimate back to the bar, or, when none does, the same Gaussian. With
  ``below_bar="climb"`` it climbs performance whenever it is below the bar, away from the target.

As in the authors' code (psclklnk/currot's ``SelfPacedTeacherV2``, checked on the ALP-GMM paper's
toy): tasks are drawn from the Gaussian truncated to the box (they reject draws outside it; here
one inverse-CDF draw per parameter, the same distribution), and the expected performance is the
plain importance-weighted mean (weights not normalised). Clipping draws instead piles them onto the
box's faces, where they are weighted as if they had been drawn there, and learns more slowly early;
the runs that showed it are on docs/results/parity.md.

Differences that remain: the covariance is diagonal (2d numbers to optimise rather than
d + d(d+1)/2; a full one needs more results per update than a curriculum service gets); the KL
divergences are exact (closed form between Gaussians) rather than sampled; the mean stays in the
box and each spread in [``MIN_SPREAD``, ``MAX_SPREAD``] (the authors bound neither by default;
freeing the mean changed nothing on the toy); the proposal is taken to be the current Gaussian,
though in a live service some tasks were drawn before the last update; the performance is success
or a scaled return rather than a value function's estimate, and the bar is on that [0, 1] scale;
the optimiser is SLSQP with exact gradients (theirs trust-constr), and a step that ends outside
its constraints is pulled back along its line, where theirs keeps a step that leaves the
estimate at 95% of the bar. TeachMyAgent's benchmark used zeta 0.25 (there the weight of a KL
penalty, SPDL's alpha schedule) and a KL limit of 0.1; both are the defaults here, zeta as the
performance bar. Without ``reward_range`` a return is placed between the lowest and highest
returns seen (``performance.py``), so the defaults work on any scale.

The update takes milliseconds of CPU (bench/self_paced_update_time.py on the shared development
machine: 3-5 ms for 6 parameters and 100-250 results, at most 15 ms for 64 parameters and 1,000
results, the largest allowed), so it runs inline every ``update_every`` results rather than as a
FitJob; SLSQP's linear algebra runs on one BLAS thread, without which a busy machine made it 10-30
times slower.

When it helps: when the hard target is known and the way there is a smooth path from easy tasks,
so that a single moving blob of tasks can follow the student (on TeachMyAgent's Parkour it is the
best teacher with the climber body and below random with the default walker). It is not for
targets spread over disconnected regions, and with the default KL limit a narrow Gaussian moves
slowly: about a tenth of its spread per update and parameter.
"""

from __future__ import annotations

import functools
import statistics
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator
from scipy.optimize import Bounds, NonlinearConstraint, minimize
from scipy.special import ndtr, ndtri
from threadpoolctl import ThreadpoolController

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms
from teacher_service.teachers.params import (
    TaskBox,
    TaskParam,
    TeacherParams,
    box_in_space,
    check_target_box,
    given_or_anchor,
)
from teacher_service.teachers.performance import RETURN_SCALE, ReturnScale, RewardRange, check_reward_range, scored
from teacher_service.teachers.state import BOOL, INT, OUTCOMES, PLAIN, FloatArray, Items, StateField

MIN_SPREAD = 1e-3
MAX_SPREAD = 1.0
"""Bounds of each standard deviation, in widths of its parameter, during the optimisation."""

MAX_ITERATIONS = 100
"""SLSQP iterations per update: bounds its cost (a few milliseconds for the sizes allowed)."""

AT_TARGET = 1e-9
"""KL divergence to the target below which the Gaussian has arrived and stays."""

KL_TOLERANCE = 1e-6
"""Relative overshoot of the KL limit accepted from the optimiser."""

PULL_BACKS = 30
"""Bisection steps that pull an overshooting step back inside its constraints."""

RECENT_MOVES = 200
"""Updates kept in the state (the oldest are dropped; ``updates`` counts them all)."""

UNIFORM_SPREAD = 12**-0.5
"""Standard deviation of the uniform distribution on [0, 1]: the ``uniform`` target's stand-in."""


class SelfPacedParams(TeacherParams):
    start: TaskParam | None = None
    """Mean of the first Gaussian; null starts at the space's easiest point."""
    initial_spread: float = Field(default=0.05, ge=MIN_SPREAD, le=MAX_SPREAD)
    """Standard deviation of the first Gaussian per parameter, in widths of the parameter."""
    target: Literal["hardest", "uniform", "box"] = "hardest"
    """Where to go: a narrow Gaussian on the space's hardest task, the uniform distribution, or the
    uniform distribution over ``target_box``."""
    target_box: TaskBox | None = None
    """With ``target`` = box (and only then): parameter name to [low, high] in task units; a
    parameter not named is held at its hardest value, and [a, a] holds it at a. Its stand-in is
    the Gaussian with the box's centre and, per parameter, the uniform's standard deviation (width
    / sqrt(12)) or ``target_spread`` if larger: a point is held as ``hardest`` holds it, and a box
    over the whole space is the ``uniform`` target (unless ``target_spread`` exceeds 0.29)."""
    target_spread: float = Field(default=0.05, ge=MIN_SPREAD, le=MAX_SPREAD)
    """Standard deviation of the ``hardest`` target per parameter, in widths of the parameter; the
    least one of the ``box`` target's."""
    zeta: float = Field(default=0.25, ge=0.0, le=1.0)
    """The bar: the expected performance (success rate, or return scaled by ``reward_range``) the
    Gaussian must keep while it moves toward the target."""
    kl_limit: float = Field(default=0.1, gt=0.0, le=10.0)
    """Most KL divergence between successive Gaussians (TeachMyAgent's benchmark: 0.1)."""
    update_every: int = Field(default=100, ge=10, le=1000)
    """Results between two updates; each update sees only the results since the last one."""
    below_bar: Literal["stay", "climb"] = "stay"
    """What an update below the bar does once the bar has been reached: ``stay`` (the authors')
    steps toward the target only to where the estimated performance reaches the bar, else keeps
    the Gaussian; ``climb`` turns toward better performance, away from the target. Before the bar
    is first reached, both climb."""
    reward_range: RewardRange | None = None
    """Returns mapped onto [0, 1] for results without ``success``; null learns it: from the lowest to
    the highest return seen so far (``train`` gives the KUKA families [0, 10])."""

    @model_validator(mode="after")
    def _consistent(self) -> SelfPacedParams:
        if self.reward_range is not None:
            check_reward_range(self.reward_range)
        check_target_box(self.target, self.target_box)
        return self


@dataclass(frozen=True)
class Gaussian:
    """A diagonal Gaussian on unit-cube tasks: its mean and the logarithm of each standard deviation."""

    mean: np.ndarray
    log_std: np.ndarray

    @property
    def weights(self) -> np.ndarray:
        return np.concatenate([self.mean, self.log_std])

    @classmethod
    def from_weights(cls, weights: np.ndarray) -> Gaussian:
        dims = len(weights) // 2
        return cls(np.array(weights[:dims], dtype=np.float64), np.array(weights[dims:], dtype=np.float64))

    def log_density(self, points: np.ndarray) -> np.ndarray:
        """Log density at ``points`` (n, d), without the constant that every Gaussian shares."""
        scaled = (points - self.mean) * np.exp(-self.log_std)
        density: np.ndarray = -self.log_std.sum() - 0.5 * np.einsum("ij,ij->i", scaled, scaled)
        return density


def kl_divergence(p: Gaussian, q: Gaussian) -> tuple[float, np.ndarray, np.ndarray]:
    """KL(p || q) between diagonal Gaussians, with its gradients in p's and in q's weights."""
    var_ratio = np.exp(2 * (p.log_std - q.log_std))
    gap = (p.mean - q.mean) * np.exp(-q.log_std)
    kl = float(np.sum(q.log_std - p.log_std + 0.5 * (var_ratio + gap**2) - 0.5))
    mean_gradient = gap * np.exp(-q.log_std)
    grad_p = np.concatenate([mean_gradient, var_ratio - 1.0])
    grad_q = np.concatenate([-mean_gradient, 1.0 - var_ratio - gap**2])
    return kl, grad_p, grad_q


def expected_performance(
    new: Gaussian, old: Gaussian, points: np.ndarray, scores: np.ndarray
) -> tuple[float, np.ndarray]:
    """The importance-weighted mean of ``scores`` (observed at ``points`` drawn from ``old``) under
    ``new``, as the authors estimate it (weights not normalised), and its gradient in ``new``'s weights."""
    with np.errstate(over="ignore"):
        weighted = np.exp(new.log_density(points) - old.log_density(points)) * scores / len(scores)
    value = float(weighted.sum())
    inverse_var = np.exp(-2 * new.log_std)
    offsets = points - new.mean
    grad_mean = weighted @ (offsets * inverse_var)
    grad_log_std = weighted @ (offsets**2 * inverse_var - 1.0)
    return value, np.concatenate([grad_mean, grad_log_std])


@dataclass(frozen=True)
class Step:
    """The outcome of one update: the new Gaussian, why, and the numbers that decided it."""

    gaussian: Gaussian
    why: str
    expected_before: float
    expected_after: float
    kl_step: float


class _Problem:
    """One update's functions in coordinates scaled to the old Gaussian: the mean's offset in its
    standard deviations and the change of log standard deviation, where the KL step is
    well-conditioned and SLSQP needs few iterations. Each function returns (value, gradient)."""

    def __init__(self, old: Gaussian, target: Gaussian, points: np.ndarray, scores: np.ndarray) -> None:
        self.old, self.target, self.points, self.scores = old, target, points, scores
        self.scale = np.concatenate([np.exp(old.log_std), np.ones(len(old.mean))])
        self._cache: tuple[bytes, tuple[float, np.ndarray]] | None = None

    def gaussian(self, x: np.ndarray) -> Gaussian:
        return Gaussian.from_weights(self.old.weights + self.scale * x)

    def bounds(self) -> Bounds:
        dims = len(self.old.mean)
        low = np.concatenate([np.zeros(dims), np.full(dims, np.log(MIN_SPREAD))])
        high = np.concatenate([np.ones(dims), np.full(dims, np.log(MAX_SPREAD))])
        return Bounds((low - self.old.weights) / self.scale, (high - self.old.weights) / self.scale)

    def to_target(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        kl, grad_p, _ = kl_divergence(self.gaussian(x), self.target)
        return kl, grad_p * self.scale

    def step_kl(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        kl, _, grad_q = kl_divergence(self.old, self.gaussian(x))
        return kl, grad_q * self.scale

    def expected(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """Cached: SLSQP asks for the value and the gradient at the same point separately."""
        key = x.tobytes()
        if self._cache is None or self._cache[0] != key:
            value, gradient = expected_performance(self.gaussian(x), self.old, self.points, self.scores)
            self._cache = (key, (value, gradient * self.scale))
        return self._cache[1]


ValueAndGradient = Callable[[np.ndarray], tuple[float, np.ndarray]]


def update_gaussian(
    old: Gaussian,
    target: Gaussian,
    points: np.ndarray,
    scores: np.ndarray,
    bar: float,
    kl_limit: float,
    climb: bool = True,
) -> Step:
    """One SPDL update (see the module docstring); deterministic for the same inputs. Below the bar
    it climbs performance when ``climb``, else steps toward the target only to where the bar holds."""
    problem = _Problem(old, target, points, scores)
    now = float(np.mean(scores))
    kl_constraint = _constraint(problem.step_kl, -np.inf, kl_limit)

    def within_kl(x: np.ndarray) -> bool:
        return problem.step_kl(x)[0] <= kl_limit * (1 + KL_TOLERANCE)

    if now >= bar or not climb:
        below = "" if now >= bar else "below the bar: "
        start_kl = problem.to_target(np.zeros(2 * len(old.mean)))[0]
        if start_kl <= AT_TARGET:
            return Step(old, "at the target", now, now, 0.0)

        def to_target(x: np.ndarray) -> tuple[float, np.ndarray]:
            """Scaled to start at 1, which suits SLSQP's tolerances whatever the distance."""
            kl, gradient = problem.to_target(x)
            return kl / start_kl, gradient / start_kl

        found = _solve(to_target, problem.bounds(), [kl_constraint, _constraint(problem.expected, bar, np.inf)])
        candidate = _pull_back(found, lambda x: within_kl(x) and problem.expected(x)[0] >= bar)
        if problem.to_target(candidate)[0] < start_kl:
            return _step(problem, candidate, f"{below}toward the target", now)
        return Step(old, f"{below}no step toward the target keeps the bar", now, now, 0.0)

    def worse(x: np.ndarray) -> tuple[float, np.ndarray]:
        value, gradient = problem.expected(x)
        return -value, -gradient

    found = _solve(worse, problem.bounds(), [kl_constraint])
    candidate = _pull_back(found, within_kl)
    if problem.expected(candidate)[0] > now:
        return _step(problem, candidate, "below the bar: toward better performance", now)
    return Step(old, "below the bar, and no better performance within reach", now, now, 0.0)


def _constraint(function: ValueAndGradient, low: float, high: float) -> NonlinearConstraint:
    """``low <= function(x) <= high``, with ``function``'s gradient as the Jacobian."""
    return NonlinearConstraint(
        lambda x: np.array([function(x)[0]]), low, high, jac=lambda x: function(x)[1][np.newaxis, :]
    )


@functools.cache
def _blas_threads() -> ThreadpoolController:
    """The loaded BLAS libraries, found once: finding them takes milliseconds."""
    return ThreadpoolController()


def _solve(objective: ValueAndGradient, bounds: Bounds, constraints: list[NonlinearConstraint]) -> np.ndarray:
    """SLSQP from the old Gaussian (the origin of the scaled coordinates), on one BLAS thread: its
    linear algebra is small, and threads waiting for cores on a busy machine made it 10-30 times
    slower."""
    with np.errstate(over="ignore", under="ignore"), _blas_threads().limit(limits=1, user_api="blas"):
        result = minimize(
            objective,
            np.zeros(len(bounds.lb)),
            jac=True,
            method="SLSQP",
            bounds=bounds,
            constraints=constraints,
            options={"maxiter": MAX_ITERATIONS},
        )
    found: np.ndarray = result.x
    return found


def _step(problem: _Problem, x: np.ndarray, why: str, now: float) -> Step:
    return Step(problem.gaussian(x), why, now, problem.expected(x)[0], problem.step_kl(x)[0])


def _pull_back(found: np.ndarray, acceptable: Callable[[np.ndarray], bool]) -> np.ndarray:
    """``found``, or when it is not ``acceptable`` (SLSQP may end a little outside its constraints)
    the farthest acceptable point found by bisection on the line from the old Gaussian to it; the
    old Gaussian when the optimiser failed outright."""
    if not np.isfinite(found).all():
        return np.zeros_like(found)
    if acceptable(found):
        return found
    near, far = 0.0, 1.0
    for _ in range(PULL_BACKS):
        middle = (near + far) / 2
        near, far = (middle, far) if acceptable(middle * found) else (near, middle)
    pulled: np.ndarray = near * found
    return pulled


GAUSSIAN_PART = FloatArray("the Gaussian's means and spreads")
"""The Gaussian's mean or log standard deviation in a snapshot: one value per dimension."""


class SelfPacedTeacher(Teacher):
    """One Gaussian over tasks, moved toward a target while the student keeps up. Scale: success when
    results carry it, else returns placed in ``reward_range``, learned from the returns seen when not
    given."""

    kind = "self-paced"
    Params = SelfPacedParams
    params: SelfPacedParams
    state_fields = (
        StateField("points", Items(FloatArray("a point"))),
        StateField("outcomes", OUTCOMES),
        StateField("return_scale", RETURN_SCALE, "scale"),
        StateField("updates", INT),
        StateField("bar_reached", BOOL),
        StateField("moves", Items(PLAIN)),
    )

    def __init__(self, space: TaskSpace, seed: int, params: SelfPacedParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        start = space.to_array(given_or_anchor("start", self.params.start, space, "easiest"))
        dims = len(space)
        self.gaussian = Gaussian(space.to_unit(start), np.full(dims, np.log(self.params.initial_spread)))
        if self.params.target_box is not None:
            low, high = box_in_space("target_box", self.params.target_box, space)
            spread = np.maximum((high - low) * UNIFORM_SPREAD, self.params.target_spread)
            self.target = Gaussian((low + high) / 2, np.log(spread))
        elif self.params.target == "hardest":
            try:
                hardest = space.to_array(space.hardest())
            except ValueError as error:
                raise ValueError(f"target 'hardest' needs a hardest value for every parameter: {error}") from None
            self.target = Gaussian(space.to_unit(hardest), np.full(dims, np.log(self.params.target_spread)))
        else:
            self.target = Gaussian(np.full(dims, 0.5), np.full(dims, np.log(UNIFORM_SPREAD)))
        self.points: list[np.ndarray] = []
        self.outcomes: list[tuple[float, bool | None]] = []
        self.scale = ReturnScale()
        self.updates = 0
        self.bar_reached = False
        self.moves: deque[dict[str, Any]] = deque(maxlen=RECENT_MOVES)

    def _draw(self, first_index: int, count: int) -> list[Task]:
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, len(self.space))
        # The Gaussian truncated to the box, by inverse CDF (one uniform per parameter): the
        # authors' rejection sampling in distribution. The mean stays in the box, so the box holds
        # at least a fifth of each parameter's mass; uniforms shifted off 0 keep a draw finite.
        mean, spread = self.gaussian.mean, np.exp(self.gaussian.log_std)
        below, inside = ndtr(-mean / spread), ndtr((1.0 - mean) / spread)
        normals = ndtri(below + (uniforms + 2.0**-54) * (inside - below))
        unit = np.clip(mean + spread * normals, 0.0, 1.0)
        return [self.space.from_array(row) for row in self.space.from_unit(unit)]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        self.points.append(self.space.to_unit(self.space.to_array(result.task)))
        self.outcomes.append((result.reward, result.success))
        self.scale.see(result.reward)
        if len(self.outcomes) == self.params.update_every:
            self._update()
        return None

    def _scores(self) -> list[float]:
        """Performance of the results since the last update, returns placed in the range as it stands."""
        reward_range = self.scale.range(self.params.reward_range)
        return [scored(reward, success, reward_range) for reward, success in self.outcomes]

    def _update(self) -> None:
        """Re-choose the Gaussian from the results since the last update (inline: milliseconds)."""
        scores = np.array(self._scores())
        step = update_gaussian(
            self.gaussian,
            self.target,
            np.array(self.points),
            scores,
            self.params.zeta,
            self.params.kl_limit,
            climb=self.params.below_bar == "climb" or not self.bar_reached,
        )
        self.bar_reached = self.bar_reached or float(np.mean(scores)) >= self.params.zeta
        self.moves.append(
            {
                "at_results": self.results_seen,
                "from": self._task(self.gaussian.mean),
                "to": self._task(step.gaussian.mean),
                "kl": step.kl_step,
                "expected_performance": step.expected_before,
                "expected_performance_after": step.expected_after,
                "kl_to_target": kl_divergence(step.gaussian, self.target)[0],
                "why": step.why,
            }
        )
        self.gaussian = step.gaussian
        self.updates += 1
        self.points.clear()
        self.outcomes.clear()

    def _task(self, unit: np.ndarray) -> Task:
        return self.space.from_array(self.space.from_unit(unit))

    def _component(self, gaussian: Gaussian) -> dict[str, Any]:
        """A Gaussian in task units, in the dashboard's component form."""
        spread = np.exp(gaussian.log_std) * (self.space.high - self.space.low)
        return {"weight": 1.0, "mean": self._task(gaussian.mean), "covariance": np.diag(spread**2).tolist()}

    def _describe(self) -> dict[str, Any]:
        return {
            "components": [self._component(self.gaussian)],
            "target": self._component(self.target),
            "target_kind": self.params.target,
            "kl_to_target": kl_divergence(self.gaussian, self.target)[0],
            "bar": self.params.zeta,
            "bar_reached": self.bar_reached,
            "updates": self.updates,
            "next_update_at_results": self.results_seen + self.params.update_every - len(self.outcomes),
            "recent_performance": statistics.fmean(self._scores()) if self.outcomes else None,
            "reward_scale": self.scale.describe(self.params.reward_range),
            "moves": list(self.moves),
        }

    def _export(self) -> dict[str, Any]:
        return {"mean": self.gaussian.mean.tolist(), "log_std": self.gaussian.log_std.tolist(), **super()._export()}

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        self.gaussian = Gaussian(
            GAUSSIAN_PART.load(state["mean"], self.gaussian.mean),
            GAUSSIAN_PART.load(state["log_std"], self.gaussian.log_std),
        )
        super()._import(state, history)
