"""Periodic evaluation during training: the deterministic policy on its task family's hardest task, over a
fixed set of seeds, logged as the run's learning curve; on a level family, the policy on held-out levels
(reset seeds outside the training set, ``common.levels.held_out_seeds``).

The seeds never change during a run, so successive evaluations differ only by the policy.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from common.client.task_space import Task
from common.kuka.task_space import task_space_for
from common.levels import held_out_seeds, is_level_env
from common.policy.trajectory import EpisodeStats

EVALUATION_SEED_OFFSET = 10_000
"""Evaluation seeds are EVALUATION_SEED_OFFSET + 0, 1, 2, ..."""


def evaluation_task(env_id: str) -> Task:
    """The hardest task of the environment's family; for ``KukaGrasp-v0`` the book's evaluation setting. A
    level family's is no task: its environment then resets with the evaluation seed, a held-out level."""
    if is_level_env(env_id):
        return {}
    return task_space_for(env_id).hardest()


def evaluation_seeds(episodes: int, env_id: str | None = None) -> list[int]:
    """The seeds of a run's evaluation episodes; a level family's are held-out levels."""
    if env_id is not None and is_level_env(env_id):
        return held_out_seeds(episodes)
    return [EVALUATION_SEED_OFFSET + index for index in range(episodes)]


def evaluation_metrics(episodes: Sequence[EpisodeStats]) -> dict[str, float]:
    return {
        "eval/return": float(np.mean([episode.reward for episode in episodes])),
        "eval/success_rate": float(np.mean([episode.success for episode in episodes])),
        "eval/episode_length": float(np.mean([episode.length for episode in episodes])),
    }
