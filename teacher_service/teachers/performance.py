"""How well the student did on one task, on a [0, 1] scale that thresholds and bars can share.

ADR and SPDL compare the student's results with thresholds. A result that says whether the episode
succeeded counts 1 or 0, so a mean is a success rate; a result without ``success`` counts its
return mapped linearly from ``reward_range`` onto [0, 1] (clipped), so a mean compares the return
with the same thresholds. The KUKA default range [0, 10] maps a grasp (about +9 to +10) to about
1 and a failed episode (about -3 to +2) to 0..0.2, so both readings of a run give close means.
The KUKA learner reports success with every result, so there the thresholds are on success rates.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from teacher_service.teachers.base import EpisodeResult

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


def performance(result: EpisodeResult, reward_range: list[float]) -> float:
    """1 or 0 from ``result.success`` when given, else the return scaled by ``reward_range``."""
    if result.success is not None:
        return 1.0 if result.success else 0.0
    low, high = reward_range
    return min(max((result.reward - low) / (high - low), 0.0), 1.0)
