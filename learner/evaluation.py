"""Periodic evaluation: the deterministic policy on the hardest task, over a fixed set of seeds.

The seeds never change during a run, so successive evaluations differ only by the policy.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from common.task_space import KUKA_TASK_SPACE
from common.trajectory import EpisodeStats

EVALUATION_TASK = KUKA_TASK_SPACE.hardest()
"""The book's evaluation setting."""
EVALUATION_SEED_OFFSET = 10_000
"""Evaluation seeds are EVALUATION_SEED_OFFSET + 0, 1, 2, ..."""


def evaluation_seeds(episodes: int) -> list[int]:
    return [EVALUATION_SEED_OFFSET + index for index in range(episodes)]


def evaluation_metrics(episodes: Sequence[EpisodeStats]) -> dict[str, float]:
    return {
        "eval/return": float(np.mean([episode.reward for episode in episodes])),
        "eval/success_rate": float(np.mean([episode.success for episode in episodes])),
        "eval/episode_length": float(np.mean([episode.length for episode in episodes])),
    }
