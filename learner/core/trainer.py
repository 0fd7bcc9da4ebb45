"""The learner's loop: pull a batch from every worker, update, broadcast the new weights.

Two layouts (``TrainConfig.loop``):

- ``async`` (the default): while the learner updates on one batch, the workers already sample the
  next with the weights they have, one update behind; each worker starts its share of the next
  batch the moment it has delivered its share of this one, so none waits for the slowest. PPO takes
  its ratio against the behaviour policy's log-probabilities that each batch carries, so a lag of
  one update stays within its trust region; ``train/policy_lag`` logs it. Evaluations queue on the
  workers behind the sampling and are collected once done, so they never stop the learner.
- ``sync``: every batch is collected with the weights the update starts from (strictly on-policy),
  and the loop pauses for each evaluation. Kept for comparison.

The weights travel through Ray's object store once per iteration (``ray.put``) and every worker
reads them from there. Stopping (the budget is spent, or ``request_stop``) only happens between
iterations, after every batch in flight has been learned from (asynchronous, a stop requested while
the next batch is already under way waits for it), so every episode the workers played is counted
and the final checkpoint is always a consistent one. The budget counts every step played, or with
``TrainConfig.budget_steps`` "trained" only the steps trained on: score-only episodes (robust PLR's
explorations) are then free, and the learning rate anneals over the trained steps.
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
from pydantic import SecretStr

from common.policy.actor_critic import PolicySnapshot
from common.policy.trajectory import EpisodeStats, TrajectoryBatch
from learner.core.checkpoint import Checkpoint, Counters, charged_steps, save_checkpoint
from learner.core.config import TrainConfig
from learner.core.metrics import MetricsLog
from learner.core.periodic_evaluation import evaluation_metrics
from learner.core.policy import policy_spec_for
from learner.core.ppo import PPOLearner
from rollout_worker.actor import TaskSourceFactory, WorkerSettings
from rollout_worker.pool import InFlight, WorkerPool
from rollout_worker.sampler import ScoreDiscount

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
        teacher_token: SecretStr | None = None,
        resume_from: Checkpoint | None = None,
        actor_name_prefix: str | None = None,
        task_source: TaskSourceFactory | None = None,
    ) -> None:
        """``actor_name_prefix`` names the rollout actors (``<prefix>-worker-<slot>-<incarnation>``)
        so that operators, and the fault tests, can find them in the Ray cluster. ``task_source``
        replaces the teacher service in every worker (``WorkerSettings.task_source``); the teacher's
        URL and curriculum are then unused."""
        torch.set_num_threads(config.ppo.torch_threads)
        self.config = config
        self.run_dir = Path(run_dir)
        self.teacher_url = teacher_url
        self.curriculum = curriculum
        self.teacher_token = teacher_token
        self.actor_name_prefix = actor_name_prefix
        self.task_source = task_source
        self.learner = PPOLearner(policy_spec_for(config.env, config.ppo, config.levels), config.ppo, config.seed)
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

    def worker_settings(self) -> WorkerSettings:
        """What every rollout actor of this run is started with, from the run's config."""
        return WorkerSettings(
            teacher_url=self.teacher_url,
            curriculum=self.curriculum,
            num_envs=self.config.envs_per_worker,
            rollout_length=self.config.ppo.rollout_length,
            max_episode_steps=self.config.max_episode_steps,
            teacher_token=self.teacher_token,
            env_id=self.config.env,
            score_discount=ScoreDiscount(
                self.config.ppo.gamma, self.config.ppo.gae_lambda, self.config.ppo.level_score
            ),
            task_source=self.task_source,
            env_options=self.config.env_options,
            task_space=self.config.task_space() if self.config.ppo.critic_task_inputs else None,
        )

    def run(self, on_iteration: Callable[[IterationReport], None] | None = None) -> Path:
        """Train until the step budget is spent or a stop is requested; return the final checkpoint."""
        settings = self.worker_settings()
        # Resumed runs draw fresh environment seeds instead of replaying the first run's.
        pool_seed = int(np.random.SeedSequence([self.config.seed, self.counters.iteration]).generate_state(1)[0])
        metrics = MetricsLog(self.run_dir)
        pool = None
        try:
            pool = WorkerPool(settings, self.config.workers, pool_seed, name_prefix=self.actor_name_prefix)
            _IterationLoop(self, pool, metrics, on_iteration).run()
            return self.save()
        finally:
            if pool is not None:
                pool.close()
            metrics.close()

    def save(self) -> Path:
        return save_checkpoint(self.run_dir, self.learner.state_dict(), self.counters, self.config)


@dataclass
class _Evaluation:
    """An evaluation in flight, and the metrics record of the iteration whose weights it plays."""

    episodes: InFlight[list[EpisodeStats]]
    record: dict[str, float]
    started: float


class _IterationLoop:
    """One ``Trainer.run``: the batch and the evaluation in flight, and the metrics records held for it.

    An iteration's record is written once its evaluation (if it has one) is in, so every record
    holds the evaluation of that iteration's weights and the log stays one record per iteration, in
    order. Records wait at most until the next checkpoint, the next evaluation or the end of the run.
    """

    def __init__(
        self,
        trainer: Trainer,
        pool: WorkerPool,
        metrics: MetricsLog,
        on_iteration: Callable[[IterationReport], None] | None,
    ) -> None:
        self.trainer = trainer
        self.config = trainer.config
        self.pool = pool
        self.metrics = metrics
        self.on_iteration = on_iteration
        self.evaluation: _Evaluation | None = None
        self.held: list[tuple[int, dict[str, float]]] = []

    def _wants_more(self, spent_after_this_batch: int) -> bool:
        return spent_after_this_batch < self.config.total_steps and not self.trainer.stop_requested

    def _spent(self) -> int:
        """The steps spent of the budget so far (``TrainConfig.budget_steps``)."""
        return self.trainer.counters.budget_spent(self.config.budget_steps)

    def _charge(self, batches: list[TrajectoryBatch]) -> int:
        """What ``batches`` add to the budget: every step, or those not score-only."""
        steps = sum(batch.num_steps for batch in batches)
        return charged_steps(steps, _score_only_steps(batches), self.config.budget_steps)

    def run(self) -> None:
        trainer, asynchronous = self.trainer, self.config.loop == "async"
        snapshot_ref = ray.put(trainer.learner.snapshot())
        if not self._wants_more(self._spent()):
            return
        in_flight: InFlight[TrajectoryBatch] | None = self.pool.start_sampling(snapshot_ref)
        while in_flight is not None:
            started = time.perf_counter()
            replacements_before = self.pool.replacements
            # Asynchronous: each worker starts its next batch, with the newest weights, the moment it has
            # delivered this one, and samples it while the learner updates; none waits for the slowest.
            # Started only if the budget is not spent even were the whole batch in flight to count; a batch of
            # score-only steps that count nothing (budget_steps "trained") leaves more, started after the update.
            following = None
            if asynchronous and self._wants_more(self._spent() + self.config.batch_size):
                following = self.pool.start_sampling(snapshot_ref, send=False)
            batches = in_flight.result(on_arrival=following.send if following is not None else None)
            sampled = time.perf_counter()
            steps = sum(batch.num_steps for batch in batches)
            go_on = following is not None or self._wants_more(self._spent() + self._charge(batches))
            in_flight = following
            progress = self._spent() / self.config.total_steps
            lag = float(np.mean([trainer.learner.version - batch.policy_version for batch in batches]))
            losses = trainer.learner.update(batches, progress, max_policy_lag=1 if asynchronous else 0)
            snapshot_ref = ray.put(trainer.learner.snapshot())
            updated = time.perf_counter()

            record = {f"loss/{name}": value for name, value in losses.items()}
            record.update(self._count(batches, self.pool.replacements - replacements_before))
            record.update(
                {
                    "train/policy_lag": lag,
                    "perf/sample_steps_per_second": steps / max(sampled - started, 1e-9),
                    "perf/wait_seconds": sampled - started,  # the learner idle, waiting for the batch
                    "perf/update_seconds": updated - sampled,  # the update and the weight broadcast
                }
            )
            self.held.append((trainer.counters.steps, record))
            if self.config.eval_every and trainer.counters.iteration % self.config.eval_every == 0:
                # Asynchronous, it queues on the workers behind the batch in flight; synchronous, it runs now.
                self._start_evaluation(snapshot_ref)
            if in_flight is None and go_on:
                in_flight = self.pool.start_sampling(snapshot_ref)
            record["perf/steps_per_second"] = steps / (time.perf_counter() - started)
            checkpoint = trainer.counters.iteration % self.config.checkpoint_every == 0
            self._write_records(wait=checkpoint or not go_on or not asynchronous)
            self._report(record)
            if checkpoint:
                trainer.save()
        self._write_records(wait=True)

    def _count(self, batches: list[TrajectoryBatch], replacements: int) -> dict[str, float]:
        counters = self.trainer.counters
        episodes = [episode for batch in batches for episode in batch.episodes]
        offline = sum(episode.task_id is None for episode in episodes)
        counters.iteration += 1
        counters.steps += sum(batch.num_steps for batch in batches)
        score_only_steps = _score_only_steps(batches)
        counters.score_only_steps += score_only_steps
        counters.episodes += len(episodes)
        counters.offline_episodes += offline
        counters.worker_replacements += replacements
        counters.results_dropped += sum(batch.results_dropped for batch in batches)
        self.trainer.recent_episodes.extend(episodes)
        return {
            "iteration": float(counters.iteration),
            "train/episodes": float(len(episodes)),
            "train/offline_episodes": float(offline),
            "train/score_only_episodes": float(sum(episode.score_only for episode in episodes)),
            "train/score_only_steps": float(score_only_steps),
            "train/episode_reward": _mean(e.reward for e in episodes),
            "train/success_rate": _mean(e.success for e in episodes),
            "train/episode_length": _mean(e.length for e in episodes),
            "workers/replacements": float(counters.worker_replacements),
            "teacher/results_waiting": float(sum(batch.results_waiting for batch in batches)),
            "teacher/results_dropped": float(counters.results_dropped),
        }

    def _start_evaluation(self, snapshot_ref: ray.ObjectRef[PolicySnapshot]) -> None:
        if self.evaluation is not None:
            self._collect_evaluation()  # still running: one at a time, in order
        episodes = self.pool.start_evaluation(
            snapshot_ref,
            self.config.evaluation_task(),
            self.config.evaluation_seeds(),
        )
        self.evaluation = _Evaluation(episodes, self.held[-1][1], time.perf_counter())

    def _collect_evaluation(self) -> None:
        assert self.evaluation is not None
        evaluation, self.evaluation = self.evaluation, None
        waited = time.perf_counter()
        episodes = [episode for share in evaluation.episodes.result() for episode in share]
        finished = time.perf_counter()
        evaluation.record.update(evaluation_metrics(episodes))
        evaluation.record["perf/eval_seconds"] = finished - evaluation.started  # from its start to its end
        evaluation.record["perf/eval_wait_seconds"] = finished - waited  # the learner idle, waiting for it

    def _write_records(self, wait: bool) -> None:
        """Write the held records up to the first whose evaluation is still running (``wait``: all of them)."""
        if self.evaluation is not None and (wait or self.evaluation.episodes.done()):
            self._collect_evaluation()
        pending = self.evaluation.record if self.evaluation is not None else None
        while self.held and self.held[0][1] is not pending:
            step, record = self.held.pop(0)
            self.metrics.write(step, record)

    def _report(self, record: dict[str, float]) -> None:
        if self.on_iteration is not None:
            trainer = self.trainer
            self.on_iteration(
                IterationReport(
                    counters=replace(trainer.counters),
                    metrics=record,
                    recent_reward=_mean(e.reward for e in trainer.recent_episodes),
                    recent_success_rate=_mean(e.success for e in trainer.recent_episodes),
                )
            )


def _score_only_steps(batches: Iterable[TrajectoryBatch]) -> int:
    """Steps of score-only episodes in ``batches``: played, left out of the update."""
    return sum(int(batch.score_only.sum()) for batch in batches if batch.score_only is not None)


def _mean(values: Iterable[float]) -> float:
    values = list(values)
    return float(np.mean(values)) if values else float("nan")
