"""How well the student did on one task, on a [0, 1] scale that thresholds and bars can share.

ADR and SPDL compare the student's results with thresholds. A result that says whether the episode
succeeded counts 1 or 0, so a mean is a success rate; a result without ``success`` counts its
return mapped linearly from ``reward_range`` onto [0, 1] (clipped), so a mean compares the return
with the same thresholds. Without a ``reward_range`` (the kinds' default) the range is learned:
the lowest and highest returns seen so far (``ReturnScale``), so the same defaults work whatever
the returns' units, and a threshold then reads "this far from the worst toward the best return
seen". ``train`` passes the KUKA range [0, 10], which maps a grasp (about +9 to +10) to about 1
and a failed episode (about -3 to +2) to 0..0.2; the KUKA learner reports success with every
result anyway, so there the thresholds are on success rates.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import Field

from teacher_service.teachers.base import EpisodeResult
from teacher_service.teachers.state import Codec

REWARD_LIMIT = 1e9
"""Largest magnitude of a ``reward_range`` end: beyond any real return, and keeps the range finite."""

KUKA_REWARD_RANGE = [0.0, 10.0]
"""The default ``reward_range``: a KUKA grasp returns about +9 to +10, a failed episode about -3 to +2."""

RewardRange = Annotated[
    list[Annotated[float, Field(ge=-REWARD_LIMIT, le=REWARD_LIMIT, allow_inf_nan=False)]],
    Field(min_length=2, max_length=2),
]
"""[low, high] of the returns mapped onto [0, 1] when a result carries no ``success``."""


def check_reward_range(reward_range: list[float]) -> None:
    """Raise ``ValueError`` unless low < high (for the parameter models' validators)."""
    if not reward_range[0] < reward_range[1]:
        raise ValueError(f"reward_range must have low < high, got {reward_range}")


UNKNOWN_SUCCESS = -1.0
"""A history row's success column when the result did not say (1 or 0 when it did)."""


def performance(result: EpisodeResult, reward_range: list[float]) -> float:
    """1 or 0 from ``result.success`` when given, else the return scaled by ``reward_range``."""
    return scored(result.reward, result.success, reward_range)


def scored(reward: float, success: bool | None, reward_range: list[float] | None) -> float:
    """1 or 0 from ``success`` when given, else ``reward`` placed in ``reward_range`` (clipped to
    [0, 1]); 0 when there is no range yet (a learned one before two different returns were seen)."""
    if success is not None:
        return 1.0 if success else 0.0
    if reward_range is None:
        return 0.0
    low, high = reward_range
    return min(max((reward - low) / (high - low), 0.0), 1.0)


class ReturnScale:
    """The lowest and highest return seen so far: the ``reward_range`` of a kind given none. Two
    numbers, whatever the number of results; results are placed in it when a decision is made, so
    a queue of rising returns is judged against the best return seen by then, not by each arrival."""

    def __init__(self, seen: list[float] | None = None) -> None:
        self.low: float | None = None if seen is None else float(seen[0])
        self.high: float | None = None if seen is None else float(seen[1])

    def see(self, reward: float) -> None:
        self.low = reward if self.low is None else min(self.low, reward)
        self.high = reward if self.high is None else max(self.high, reward)

    def range(self, given: list[float] | None = None) -> list[float] | None:
        """``given`` when there is one, else the learned range once it spans two different returns."""
        if given is not None:
            return given
        if self.low is None or self.high is None or not self.low < self.high:
            return None
        return [self.low, self.high]

    def at(self, share: float) -> float | None:
        """The return ``share`` of the way from the lowest to the highest seen; ``None`` until two
        different returns were seen."""
        seen = self.range()
        return None if seen is None else seen[0] + share * (seen[1] - seen[0])

    def export(self) -> list[float] | None:
        return None if self.low is None or self.high is None else [self.low, self.high]

    def describe(self, given: list[float] | None) -> dict[str, Any]:
        """Which range scores returns, for the dashboard: the given one or what was learned."""
        if given is not None:
            return {"source": "given", "range": list(given)}
        return {"source": "learned from the returns seen", "range": self.export()}


class _ScaleCodec(Codec):
    """A ``ReturnScale`` in a snapshot: the lowest and highest return seen, or ``None`` before any."""

    def dump(self, value: Any) -> Any:
        return value.export()

    def load(self, data: Any, fresh: Any) -> Any:
        return ReturnScale(data)


RETURN_SCALE = _ScaleCodec()
