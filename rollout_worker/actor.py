"""The rollout actor: environments of a run's task family (``common.families``), a teacher client and the
sampling loop in one Ray process.

Every episode's task comes from the teacher service and its result goes straight back there; the
learner only ever receives fixed-size batches. Weights arrive as a ``PolicySnapshot``; passing a
``ray.put`` reference lets Ray fetch it from the object store once per worker. Nothing here imports
torch (the policy runs in numpy, ``common.policy.inference``): loading it was most of a worker's
start-up time.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import ray
from pydantic import SecretStr

from common.client.task_space import Task, TaskSpace
from common.client.teacher_client import Assignment, TeacherClient
from common.families import family_for
from common.kuka import ENV_ID
from common.policy.inference import InferencePolicy, PolicySnapshot
from common.policy.trajectory import EpisodeStats, TrajectoryBatch
from rollout_worker.sampler import Sampler, ScoreDiscount, TaskSource, run_episodes

TASK_TIMEOUT_S = 2.0
"""How long a worker waits for the teacher before playing an offline episode: short, because
every environment whose episode ends during an outage pays it."""


TaskSourceFactory = Callable[[int], TaskSource]
"""Builds a worker's task source from the worker's seed, inside the worker (so it must pickle)."""


@dataclass(frozen=True)
class WorkerSettings:
    """What every worker of a run shares."""

    teacher_url: str
    curriculum: str
    num_envs: int
    rollout_length: int
    max_episode_steps: int
    teacher_token: SecretStr | None = None
    """Held as a ``SecretStr`` so that no repr or log line of the settings shows it."""
    env_id: str = ENV_ID
    """The environment the workers step, of any task family (``common.families``)."""
    score_discount: ScoreDiscount | None = None
    """The learner's discount and GAE lambda, and which score each episode's result carries (robust PLR's
    positive value loss or the PLR paper's value_l1; None: results go without a score)."""
    results_buffer: int = 100_000
    """Most results a worker's client holds through a teacher outage before dropping the oldest
    (``TeacherClient.max_buffered_results``, about 0.6 KB each)."""
    task_source: TaskSourceFactory | None = None
    """Where tasks come from and results go instead of the teacher service (None: the service at
    ``teacher_url``): a benchmark's stand-in, such as no curriculum at all or another library's
    curriculum, run with the same workers and learner."""
    env_options: Mapping[str, Any] = field(default_factory=dict)
    """The family's training-only options for the training environments (a hard KUKA family's
    ``edge_placement_share``); evaluation episodes play the environment without them."""
    task_space: TaskSpace | None = None
    """The run's task space, which scales each episode's task for a critic that reads it (None: it reads none)."""


class _TeacherTasks:
    """Adapts the teacher client to the sampler's ``TaskSource``."""

    def __init__(self, client: TeacherClient) -> None:
        self.client = client

    def next_task(self) -> Assignment:
        return self.client.next_task()

    def report(self, episode: EpisodeStats) -> None:
        self.client.report(
            Assignment(episode.task_id, episode.task),
            episode.reward,
            success=episode.success,
            length=episode.length,
            score=episode.score,
        )


@ray.remote(num_cpus=1)
class RolloutWorker:
    """One CPU's worth of environments; every call runs on the weights it is handed."""

    def __init__(self, settings: WorkerSettings, seed: int) -> None:
        self.settings = settings
        self.seed = seed
        self.client: TeacherClient | None = None
        tasks: TaskSource
        if settings.task_source is not None:
            tasks = settings.task_source(seed)
        else:
            self.client = TeacherClient(
                settings.teacher_url,
                settings.curriculum,
                token=settings.teacher_token,
                prefetch=2 * settings.num_envs,
                task_timeout=TASK_TIMEOUT_S,
                max_buffered_results=settings.results_buffer,
            )
            tasks = _TeacherTasks(self.client)
        self.family = family_for(settings.env_id)
        envs = [
            self.family.make_env(settings.env_id, settings.max_episode_steps, options=settings.env_options)
            for _ in range(settings.num_envs)
        ]
        self.sampler = Sampler(envs, tasks, seed, settings.score_discount, settings.task_space)
        self.evaluation_env: gym.Env[np.ndarray, Any] | None = None
        self.policy: InferencePolicy | None = None
        self._dropped_reported = 0

    def _load(self, snapshot: PolicySnapshot) -> InferencePolicy:
        if self.policy is None:
            self.policy = InferencePolicy(snapshot, seed=self.seed)
        elif self.policy.version != snapshot.version:
            self.policy.load(snapshot)
        return self.policy

    def sample(self, snapshot: PolicySnapshot) -> TrajectoryBatch:
        """A batch on these weights, with the teacher client's delivery counters (see ``TrajectoryBatch``)."""
        batch = self.sampler.sample(self._load(snapshot), self.settings.rollout_length)
        if self.client is None:
            return batch
        dropped_in_all = self.client.dropped_results
        dropped, self._dropped_reported = dropped_in_all - self._dropped_reported, dropped_in_all
        return dataclasses.replace(batch, results_waiting=self.client.pending, results_dropped=dropped)

    def evaluate(self, snapshot: PolicySnapshot, task: Task, seeds: Sequence[int]) -> list[EpisodeStats]:
        """Episodes on an environment of their own, so training episodes are not disturbed, acting as the family
        evaluates (``TaskFamily.deterministic_evaluation``)."""
        if self.evaluation_env is None:
            self.evaluation_env = self.family.make_env(self.settings.env_id, self.settings.max_episode_steps)
        deterministic = self.family.deterministic_evaluation
        return run_episodes(self.evaluation_env, self._load(snapshot), task, seeds, deterministic=deterministic)

    def close(self) -> None:
        """Deliver every buffered episode result to the teacher."""
        if self.client is not None:
            self.client.close()
