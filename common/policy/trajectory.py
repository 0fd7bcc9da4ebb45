"""What a rollout worker hands the learner: a fixed-size batch of steps and the episodes it finished."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common.client.task_space import Task


@dataclass(frozen=True)
class EpisodeStats:
    """One finished episode and the task it was played on.

    ``task_id`` is the id the teacher issued the task under; None when no teacher issued it (an
    evaluation episode, or an offline episode played while the teacher was unreachable).
    """

    task: Task
    reward: float
    success: bool
    length: int
    task_id: str | None = None
    score: float | None = None
    """The episode's level score from its GAE advantages, computed with the values the policy predicted as it
    acted: robust PLR's positive value loss (the mean of max(advantage, 0)) or the PLR paper's value_l1 (the
    mean of |advantage|), as the run chose (None where the sampler computes none, as in evaluations)."""
    score_only: bool = False
    """The teacher issued the task for scoring only (robust PLR): its steps stay out of the policy update."""


@dataclass(frozen=True)
class TrajectoryBatch:
    """Time-major arrays of shape (steps, envs, ...) collected with one policy version.

    Observations are raw (unnormalised): the learner normalises them with the statistics it sent
    and then folds them into its running statistics. Episodes cross batch boundaries, so two arrays
    carry what bootstrapping needs: ``final_values`` holds V(last observation) at steps where an
    episode was truncated (zero elsewhere), and ``last_values`` holds V(next observation) for every
    environment after the final step. ``score_only`` marks the steps of episodes whose task was issued for
    scoring only: they are played and reported, and their advantages computed, but the update leaves
    them out (None: no such step). ``critic_tasks`` holds, for a critic that reads the task, each step's
    episode's task as the workers' critic read it (None: the critic reads none).
    """

    observations: np.ndarray
    actions: np.ndarray
    log_probs: np.ndarray
    values: np.ndarray
    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    final_values: np.ndarray
    last_values: np.ndarray
    policy_version: int
    episodes: list[EpisodeStats] = field(default_factory=list)
    score_only: np.ndarray | None = None
    critic_tasks: np.ndarray | None = None
    """(steps, envs, critic_task_dim) float32: the task parameters, each scaled to [0, 1] by the run's task space."""
    results_waiting: int = 0
    """Results the worker's teacher client held for delivery when the batch was made (an outage
    shows here first)."""
    results_dropped: int = 0
    """Results the worker's client dropped since its previous batch: the oldest, once an outage
    filled its buffer (``TeacherClient.max_buffered_results``)."""

    @property
    def num_steps(self) -> int:
        return int(self.rewards.size)
