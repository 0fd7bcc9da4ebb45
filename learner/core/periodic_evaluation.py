"""Periodic evaluation during training: the policy on its family's evaluation task (the hardest task, or
held-out levels) over a fixed set of seeds, logged as the run's learning curve. The seeds never change during
a run, so successive evaluations differ only by the policy; which seeds is the family's to say
(``TaskFamily.evaluation_seeds``; a KUKA family's ``stratified`` ones in ``common.kuka.evaluation_seeds``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from common.policy.trajectory import EpisodeStats


def evaluation_metrics(episodes: Sequence[EpisodeStats]) -> dict[str, float]:
    return {
        "eval/return": float(np.mean([episode.reward for episode in episodes])),
        "eval/success_rate": float(np.mean([episode.success for episode in episodes])),
        "eval/episode_length": float(np.mean([episode.length for episode in episodes])),
    }
