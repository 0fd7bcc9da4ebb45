"""The learner's loop: pull a batch from every worker, update, broadcast the new weights.

Synchronous on purpose: every batch is collected with the weights the update starts from, so PPO
stays on-policy. The weights travel through Ray's object store once per iteration (``ray.put``)
and every worker reads them from there. Stopping (the budget is spent, or ``request_stop``) only
happens between iterations, so the final checkpoint is always a consistent one.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import ray
import torch

from common.policy import PolicySnapshot
from common.trajectory import EpisodeStats
from learner.checkpoint import Checkpoint, Counters, save_checkpoint
from learner.config import TrainConfig
from learner.evaluation import evaluate_on_hardest_task
from learner.metrics import MetricsLog
from learner.network import kuka_policy_spec
from learner.ppo import PPOLearner
from rollout_worker.actor import WorkerSettings
from rollout_worker.pool import WorkerPool

RECENT_EPISODES = 100
"""Window of the running reward and success rate shown while training."""


@dataclass(frozen=True)
class IterationReport:
    """What one iteration did, for progress displays; the same metrics go to the metrics log."""

    counters: Counters
    metrics: dict[str, float]
    recent_reward: float
    recent_success_rate: float


class Trainer:
    """Owns the learner, the counters and, while ``run`` runs, the rollout workers."""

    def __init__(
        self,
        config: TrainConfig,
        run_dir: Path,
        teacher_url: str,
        curriculum: str,
        teacher_token: str | None = None,
        resume_from: Checkpoint | None = None,
        actor_name_prefix: str | None = None,
    ) -> None:
        """``actor_name_prefix`` names the rollout actors (``<prefix>-worker-<slot>-<incarnation>``)
        so that operators, and the fault tests, can find them in the Ray cluster."""
        torch.set_num_threads(config.ppo.torch_threads)
        self.config = config
        self.run_dir = Path(run_dir)
        self.teacher_url = teacher_url
        self.curriculum = curriculum
        self.teacher_token = teacher_token
        self.actor_name_prefix = actor_name_prefix
        self.learner = PPOLearner(kuka_policy_spec(config.ppo), config.ppo, config.seed)
        self.counters = Counters()
        if resume_from is not None:
            self.learner.load_state_dict(resume_from.learner)
            self.counters = replace(resume_from.counters)
        self.recent_episodes: deque[EpisodeStats] = deque(maxlen=RECENT_EPISODES)
        self._stop_requested = False

    @property
    def stop_requested(self) -> bool:
        return self._stop_requested

    def request_stop(self) -> None:
        """Finish the current iteration, write a checkpoint and return (safe from a signal handler)."""
        self._stop_requested = True

    def run(self, on_iteration: Callable[[IterationReport], None] | None = None) -> Path:
        """Train until the step budget is spent or a stop is requested; return the final checkpoint."""
        settings = WorkerSettings(
            teacher_url=self.teacher_url,
            curriculum=self.curriculum,
            num_envs=self.config.envs_per_worker,
            rollout_length=self.config.ppo.rollout_length,
            max_episode_steps=self.config.max_episode_steps,
            teacher_token=self.teacher_token,
        )
        # Resumed runs draw fresh environment seeds instead of replaying the first run's.
        pool_seed = int(np.random.SeedSequence([self.config.seed, self.counters.iteration]).generate_state(1)[0])
        metrics = MetricsLog(self.run_dir)
        pool = None
        try:
            pool = WorkerPool(settings, self.config.workers, pool_seed, name_prefix=self.actor_name_prefix)
            snapshot_ref = ray.put(self.learner.snapshot())
            while self.counters.steps < self.config.total_steps and not self._stop_requested:
                snapshot_ref, report = self._iterate(pool, snapshot_ref)
                metrics.write(self.counters.steps, report.metrics)
                if on_iteration is not None:
                    on_iteration(report)
                if self.counters.iteration % self.config.checkpoint_every == 0:
                    self.save()
            return self.save()
        finally:
            if pool is not None:
                pool.close()
            metrics.close()

    def save(self) -> Path:
        return save_checkpoint(self.run_dir, self.learner.state_dict(), self.counters, self.config)

    def _iterate(
        self, pool: WorkerPool, snapshot_ref: ray.ObjectRef[PolicySnapshot]
    ) -> tuple[ray.ObjectRef[PolicySnapshot], IterationReport]:
        started = time.perf_counter()
        replacements_before = pool.replacements
        batches = pool.sample(snapshot_ref)
        sampled = time.perf_counter()
        progress = self.counters.steps / self.config.total_steps
        metrics = {f"loss/{name}": value for name, value in self.learner.update(batches, progress).items()}
        snapshot_ref = ray.put(self.learner.snapshot())
        updated = time.perf_counter()

        steps = sum(batch.num_steps for batch in batches)
        episodes = [episode for batch in batches for episode in batch.episodes]
        self.counters.iteration += 1
        self.counters.steps += steps
        offline = sum(episode.task_id is None for episode in episodes)
        self.counters.episodes += len(episodes)
        self.counters.offline_episodes += offline
        self.counters.worker_replacements += pool.replacements - replacements_before
        self.recent_episodes.extend(episodes)
        metrics.update(
            {
                "iteration": float(self.counters.iteration),
                "train/episodes": float(len(episodes)),
                "train/offline_episodes": float(offline),
                "train/episode_reward": _mean(e.reward for e in episodes),
                "train/success_rate": _mean(e.success for e in episodes),
                "train/episode_length": _mean(e.length for e in episodes),
                "perf/sample_steps_per_second": steps / (sampled - started),
                "perf/steps_per_second": steps / (updated - started),
                "perf/update_seconds": updated - sampled,  # the update and the weight broadcast
                "workers/replacements": float(self.counters.worker_replacements),
            }
        )
        if self.config.eval_every and self.counters.iteration % self.config.eval_every == 0:
            metrics.update(evaluate_on_hardest_task(pool, snapshot_ref, self.config.eval_episodes))
            metrics["perf/eval_seconds"] = time.perf_counter() - updated
        report = IterationReport(
            counters=replace(self.counters),
            metrics=metrics,
            recent_reward=_mean(e.reward for e in self.recent_episodes),
            recent_success_rate=_mean(e.success for e in self.recent_episodes),
        )
        return snapshot_ref, report


def _mean(values: Iterable[float]) -> float:
    values = list(values)
    return float(np.mean(values)) if values else float("nan")
