"""ADR, Automatic Domain Randomization (OpenAI et al. 2019, "Solving Rubik's Cube with a Robot Hand").

The teacher keeps a box of task bounds that starts at the easiest task (a point, or a small box
around it) and grows toward the whole space while the student copes with its edges. A task is,
with probability ``boundary_prob``, pinned at one open boundary (a low or high bound not yet at
the space's limit) with the other parameters uniform in the box; otherwise it is uniform in the
box. Every result whose task lies on a boundary is queued for that boundary (exact equality, as
the tasks handed out carry the bound's exact value; a parameter whose bounds still coincide puts
every result on both). When a queue holds ``queue_length`` results, their mean performance
(``performance.py``: success rate, or the return placed in ``reward_range``; without one, between
the lowest and highest returns seen so far, so the defaults work on any scale) at or above
``upper_threshold`` moves that bound ``step`` of the parameter's width outward, at or below
``lower_threshold`` moves it back inward; then the queue is emptied. A queue holds the raw results
and is judged with the range as it stands when it is full.

Checked against its sources for issue 48: OpenAI et al. 2019 (Algorithm 1: pin one parameter at
one of its bounds, record the performance in that bound's buffer, and when the buffer holds m
results move the bound by a fixed step outward at or above t_H, inward at or below t_L, then clear
it) and TeachMyAgent's ``ADR`` (Romac et al. 2021, teachers/algos/adr.py). The update rule is theirs;
nothing was found that needed fixing. Where ours differs, and why:

- like TeachMyAgent, a result feeds every bound its task lies on, not only the one it was pinned to
  (the paper's rule); with continuous parameters that matters only while a parameter's bounds
  coincide, where it fills both of its queues at once, as in TeachMyAgent;
- the pinned boundary is drawn uniformly among the open ones; TeachMyAgent and the paper draw a
  parameter and then a side, and TeachMyAgent pins nothing when the drawn parameter is at both
  limits. From the easiest corner (every parameter at a limit) the two agree;
- a bound never narrows past the starting box (TeachMyAgent lets it move until it meets the
  opposite bound, the paper states no limit), so the box always holds the easiest task;
- the step is a share of the parameter's range and the thresholds are on the [0, 1] performance
  scale (TeachMyAgent: a step in the parameter's units and thresholds on the raw return, optionally
  rescaled; the paper: a step per parameter and thresholds on a success count).

TeachMyAgent's benchmark settings (boundary probability 0.7, step 0.1 of the width, queues of 10)
are the defaults (its class's own default boundary probability is 0.5).

When it helps: when the easiest task is known and difficulty grows outward from it along each
parameter, so that mastering the edge of what is mastered is the way forward. It is slow where
most of the space is infeasible (TeachMyAgent's Parkour ranks it last) and needs thresholds that
fit the student's returns.
"""

from __future__ import annotations

import statistics
from collections import deque
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms
from teacher_service.teachers.params import TaskParam, TeacherParams, given_or_anchor
from teacher_service.teachers.performance import RETURN_SCALE, ReturnScale, RewardRange, check_reward_range, scored
from teacher_service.teachers.state import INT, OUTCOMES, PLAIN, FloatArray, Items, StateField

RECENT_MOVES = 200
"""Boundary moves kept in the state (the oldest are dropped; the totals count them all). A move's
``from`` and ``to`` hold only the parameter that moved, so the state stays small in large spaces."""

SNAP = 1e-9
"""A bound that ends this close to its limit (in widths of its parameter) is put on it: sums of
0.1 steps fall short of 1 by rounding."""

Side = Literal["low", "high"]
SIDES: tuple[Side, Side] = ("low", "high")


class AdrParams(TeacherParams):
    start: TaskParam | None = None
    """Centre of the starting box; null starts at the space's easiest point."""
    initial_width: float = Field(default=0.0, ge=0.0, le=1.0)
    """Width of the starting box per parameter, as a share of the parameter's range (clipped to the
    space); 0 starts from the single point, as the paper does."""
    boundary_prob: float = Field(default=0.7, ge=0.0, le=1.0)
    """Share of tasks pinned at an open boundary (TeachMyAgent's benchmark used 0.7)."""
    step: float = Field(default=0.1, gt=0.0, le=1.0)
    """How far a bound moves, as a share of its parameter's range (TeachMyAgent: 0.1)."""
    queue_length: int = Field(default=10, ge=1, le=1000)
    """Results at a boundary that decide whether it moves (TeachMyAgent: 10)."""
    upper_threshold: float = Field(default=0.8, ge=0.0, le=1.0)
    """Widen a boundary when its queue's mean performance is at least this."""
    lower_threshold: float = Field(default=0.2, ge=0.0, le=1.0)
    """Narrow a boundary when its queue's mean performance is at most this."""
    reward_range: RewardRange | None = None
    """Returns mapped onto [0, 1] for results without ``success``; null learns it: from the lowest to
    the highest return seen so far (``train`` gives the KUKA families [0, 10])."""

    @model_validator(mode="after")
    def _consistent(self) -> AdrParams:
        if not self.lower_threshold < self.upper_threshold:
            raise ValueError(
                f"lower_threshold ({self.lower_threshold}) must be below upper_threshold ({self.upper_threshold})"
            )
        if self.reward_range is not None:
            check_reward_range(self.reward_range)
        return self


class AdrTeacher(Teacher):
    """A box of tasks that widens at boundaries the student masters. Scale: success when results
    carry it, else returns placed in ``reward_range``, learned from the returns seen when not given.
    """

    kind = "adr"
    Params = AdrParams
    params: AdrParams
    state_fields = (
        StateField("low", FloatArray("low")),
        StateField("high", FloatArray("high")),
        StateField("return_scale", RETURN_SCALE, "scale"),
        StateField("moves", Items(PLAIN)),
        StateField("widened", INT),
        StateField("narrowed", INT),
    )

    def __init__(self, space: TaskSpace, seed: int, params: AdrParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        start = space.to_array(given_or_anchor("start", self.params.start, space, "easiest"))
        half = self.params.initial_width * (space.high - space.low) / 2
        self.initial_low = np.maximum(start - half, space.low)
        self.initial_high = np.minimum(start + half, space.high)
        self.low = self.initial_low.copy()
        self.high = self.initial_high.copy()
        self.queues: dict[tuple[int, Side], list[tuple[float, bool | None]]] = {
            (d, side): [] for d in range(len(space)) for side in SIDES
        }
        self.scale = ReturnScale()
        self.moves: deque[dict[str, Any]] = deque(maxlen=RECENT_MOVES)
        self.widened = 0
        self.narrowed = 0

    def _open_boundaries(self) -> list[tuple[int, Side]]:
        """Boundaries not yet at the space's limit, in a fixed order."""
        open_: list[tuple[int, Side]] = []
        for d in range(len(self.space)):
            if self.low[d] > self.space.low[d]:
                open_.append((d, "low"))
            if self.high[d] < self.space.high[d]:
                open_.append((d, "high"))
        return open_

    def _draw(self, first_index: int, count: int) -> list[Task]:
        dims = len(self.space)
        # Per task: the pinning coin, the boundary choice, then one uniform per parameter.
        uniforms = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, 2 + dims)
        tasks = self.low + uniforms[:, 2:] * (self.high - self.low)
        boundaries = self._open_boundaries()
        if boundaries:
            for row, (coin, choice) in enumerate(uniforms[:, :2]):
                if coin < self.params.boundary_prob:
                    d, side = boundaries[min(int(choice * len(boundaries)), len(boundaries) - 1)]
                    tasks[row, d] = self.low[d] if side == "low" else self.high[d]
        return [self.space.from_array(row) for row in tasks]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        task = self.space.to_array(result.task)
        self.scale.see(result.reward)
        outcome = (result.reward, result.success)
        for d in range(len(self.space)):
            if task[d] == self.low[d]:
                self._queue(d, "low", outcome)
            if task[d] == self.high[d]:
                self._queue(d, "high", outcome)
        return None

    def _mean_performance(self, queue: list[tuple[float, bool | None]]) -> float:
        """The queue's mean performance, its returns placed in the range as it stands now."""
        reward_range = self.scale.range(self.params.reward_range)
        return statistics.fmean(scored(reward, success, reward_range) for reward, success in queue)

    def _queue(self, d: int, side: Side, outcome: tuple[float, bool | None]) -> None:
        queue = self.queues[d, side]
        queue.append(outcome)
        if len(queue) < self.params.queue_length:
            return
        mean = self._mean_performance(queue)
        queue.clear()
        if mean >= self.params.upper_threshold:
            self._move(d, side, outward=True, mean=mean)
        elif mean <= self.params.lower_threshold:
            self._move(d, side, outward=False, mean=mean)

    def _move(self, d: int, side: Side, outward: bool, mean: float) -> None:
        """Move one bound by ``step`` of its width: outward up to the space's limit, inward down
        to the starting box."""
        width = self.space.high[d] - self.space.low[d]
        current = self.low[d] if side == "low" else self.high[d]
        if outward:
            limit = self.space.low[d] if side == "low" else self.space.high[d]
        else:
            limit = self.initial_low[d] if side == "low" else self.initial_high[d]
        moved = current + (self.params.step * width if (side == "high") == outward else -self.params.step * width)
        if (moved - limit) * (limit - current) >= 0 or abs(moved - limit) <= SNAP * width:
            moved = limit  # stepped past the limit, or short of it by rounding (ten steps of 0.1)
        if moved == current:
            return
        if side == "low":
            self.low[d] = moved
        else:
            self.high[d] = moved
        if outward:
            self.widened += 1
        else:
            self.narrowed += 1
        threshold = "upper" if outward else "lower"
        self.moves.append(
            {
                "at_results": self.results_seen,
                "parameter": self.space.names[d],
                "side": side,
                "from": {self.space.names[d]: float(current)},
                "to": {self.space.names[d]: float(moved)},
                "performance": mean,
                "why": (
                    f"{'widened' if outward else 'narrowed'}: mean performance {mean:.3g} over "
                    f"{self.params.queue_length} results at {self.space.names[d]}'s {side} bound "
                    f"{'>=' if outward else '<='} {threshold}_threshold"
                ),
            }
        )

    def bounds(self) -> dict[str, Task]:
        """The current box, in task units."""
        return {"low": self.space.from_array(self.low), "high": self.space.from_array(self.high)}

    def _describe(self) -> dict[str, Any]:
        open_ = set(self._open_boundaries())
        boundaries = []
        for (d, side), queue in self.queues.items():
            boundaries.append(
                {
                    "parameter": self.space.names[d],
                    "side": side,
                    "value": float(self.low[d] if side == "low" else self.high[d]),
                    "at_limit": (d, side) not in open_,
                    "queued": len(queue),
                    "queue_mean": self._mean_performance(queue) if queue else None,
                }
            )
        return {
            "bounds": {**self.bounds(), "boundaries": boundaries},
            "moves": list(self.moves),
            "widened": self.widened,
            "narrowed": self.narrowed,
            "full_space": not open_,
            "reward_scale": self.scale.describe(self.params.reward_range),
        }

    def _export(self) -> dict[str, Any]:
        return {
            **super()._export(),
            "queues": [[self.space.names[d], side, OUTCOMES.dump(queue)] for (d, side), queue in self.queues.items()],
        }

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        super()._import(state, history)
        index = {name: d for d, name in enumerate(self.space.names)}
        for name, side, queue in state["queues"]:
            self.queues[index[name], side] = OUTCOMES.load(queue, [])
