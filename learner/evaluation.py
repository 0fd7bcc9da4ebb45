"""Periodic evaluation: the deterministic policy on the hardest task, over a fixed set of seeds.

The seeds never change during a run, so successive evaluations differ only by the policy.
"""

from __future__ import annotations

import numpy as np
import ray

from common.policy import PolicySnapshot
from common.task_space import KUKA_TASK_SPACE
from rollout_worker.pool import WorkerPool

EVALUATION_SEED_OFFSET = 10_000
"""Evaluation seeds are EVALUATION_SEED_OFFSET + 0, 1, 2, ..."""


def evaluation_seeds(episodes: int) -> list[int]:
    return [EVALUATION_SEED_OFFSET + index for index in range(episodes)]


def evaluate_on_hardest_task(
    pool: WorkerPool, snapshot: ray.ObjectRef[PolicySnapshot] | PolicySnapshot, episodes: int
) -> dict[str, float]:
    results = pool.evaluate(snapshot, KUKA_TASK_SPACE.hardest(), evaluation_seeds(episodes))
    return {
        "eval/return": float(np.mean([episode.reward for episode in results])),
        "eval/success_rate": float(np.mean([episode.success for episode in results])),
        "eval/episode_length": float(np.mean([episode.length for episode in results])),
    }
