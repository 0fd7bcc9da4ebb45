"""Proximal Policy Optimisation: GAE advantages and the clipped-surrogate update.

Pure torch and numpy: batches in, metrics out. The learner owns the network, the optimiser and the
observation normaliser; ``snapshot()`` is what the workers act with.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import nn

from common.policy.actor_critic import ActorCritic, ObservationFeatures, PolicySnapshot, PolicySpec, capture_snapshot
from common.policy.normalizer import NORMALIZER_EPSILON, NormalizerState, RunningNormalizer
from common.policy.trajectory import TrajectoryBatch
from learner.core.checkpoint import RESUME_ONLY_STATE, EvaluationOnlyCheckpointError
from learner.core.config import PPOConfig


def compute_advantages(batch: TrajectoryBatch, gamma: float, gae_lambda: float) -> tuple[np.ndarray, np.ndarray]:
    """Generalised advantage estimates and value targets, both (steps, envs).

    A terminated episode bootstraps from zero; a truncated one from the value of its last
    observation (it could have gone on); the chain of lambda-returns never crosses an episode end.
    """
    advantages = np.zeros_like(batch.rewards, dtype=np.float64)
    running = np.zeros(batch.rewards.shape[1], dtype=np.float64)
    next_values = batch.last_values.astype(np.float64)
    for step in reversed(range(batch.rewards.shape[0])):
        ended = batch.terminated[step] | batch.truncated[step]
        bootstrap = np.where(batch.truncated[step], batch.final_values[step], next_values)
        bootstrap = np.where(batch.terminated[step], 0.0, bootstrap)
        delta = batch.rewards[step] + gamma * bootstrap - batch.values[step]
        running = delta + gamma * gae_lambda * ~ended * running
        advantages[step] = running
        next_values = batch.values[step]
    return advantages, advantages + batch.values


def annealed_learning_rate(config: PPOConfig, progress: float) -> float:
    """The step size after ``progress`` (share of the budget spent, in [0, 1]): with ``anneal_lr``, a
    straight line from ``learning_rate`` down to ``lr_final_fraction`` of it at the end of the budget."""
    if not config.anneal_lr:
        return config.learning_rate
    spent = min(max(progress, 0.0), 1.0)
    return config.learning_rate * (1.0 - spent * (1.0 - config.lr_final_fraction))


class PPOLosses(NamedTuple):
    """One minibatch's losses: ``total`` is what the optimiser minimises, the rest are its parts and
    diagnostics (the statistics ``PPOLearner.update`` averages into its metrics)."""

    total: torch.Tensor
    policy_loss: torch.Tensor
    value_loss: torch.Tensor
    entropy: torch.Tensor
    approx_kl: torch.Tensor
    clip_fraction: torch.Tensor


def ppo_losses(
    new_log_probs: torch.Tensor,
    old_log_probs: torch.Tensor,
    advantages: torch.Tensor,
    new_values: torch.Tensor,
    old_values: torch.Tensor,
    returns: torch.Tensor,
    entropy: torch.Tensor,
    config: PPOConfig,
) -> PPOLosses:
    """The clipped-surrogate, value and entropy terms for one minibatch, each input one entry per step.

    A pure function of its tensors (no network, no optimiser) so that a fixed minibatch can be checked
    by hand. The policy loss takes the pessimistic (larger) of the unclipped and clipped surrogates;
    with ``clip_value_loss`` the value loss takes the larger of the two squared errors.
    """
    log_ratio = new_log_probs - old_log_probs
    ratio = log_ratio.exp()

    adv = advantages
    if config.normalize_advantages and len(adv) > 1:
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
    clipped_ratio = ratio.clamp(1 - config.clip_coef, 1 + config.clip_coef)
    policy_loss = torch.max(-adv * ratio, -adv * clipped_ratio).mean()

    value_error = (new_values - returns) ** 2
    if config.clip_value_loss:
        clipped = old_values + (new_values - old_values).clamp(-config.clip_coef, config.clip_coef)
        value_error = torch.max(value_error, (clipped - returns) ** 2)
    value_loss = 0.5 * value_error.mean()

    total = policy_loss - config.entropy_coef * entropy.mean() + config.value_coef * value_loss
    with torch.no_grad():
        approx_kl = ((ratio - 1) - log_ratio).mean()
        clip_fraction = ((ratio - 1).abs() > config.clip_coef).float().mean()
    return PPOLosses(total, policy_loss, value_loss, entropy.mean(), approx_kl, clip_fraction)


class PPOLearner:
    """The network, its optimiser and the observation statistics; ``version`` counts updates.

    An image spec's normaliser is never updated nor applied (``PolicySpec.normalizes_observations``): its
    encoder scales the pixels itself. It is kept, at its start, so that checkpoints and snapshots hold the
    same state whatever the observation.

    With ``normalize_values`` the critic learns value targets standardised by the mean and std of every target
    so far (``value_statistics``), and each snapshot folds those back into the critic's last layer, so the
    workers' values, and with them GAE and PLR's scores, stay in return units. That rather than SB3's or
    CleanRL's reward scaling, which divides the rewards themselves and would hand GAE and the teacher values
    in other units. When the statistics move, the critic's last layer is rescaled so that its predictions stay
    what they were (PopArt's "preserving outputs precisely", van Hasselt et al. 2016) instead of jumping with
    them; statistics over all targets, not a decaying average, leave no rate to tune.
    """

    def __init__(self, spec: PolicySpec, config: PPOConfig, seed: int) -> None:
        self.config = config
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            self.network = ActorCritic(spec)
        # The fused kernel does Adam's per-parameter updates in one call: a third off each step on CPU.
        self.optimizer = torch.optim.Adam(
            self.network.parameters(), lr=config.learning_rate, eps=config.adam_eps, fused=True
        )
        self.features = ObservationFeatures(spec)
        self.normalizer = RunningNormalizer(spec.feature_dim, clip=config.obs_clip)
        self.value_statistics = RunningNormalizer(1) if config.normalize_values else None
        """The running mean and variance of the value targets (only its statistics are used), or None."""
        self.shuffle = torch.Generator().manual_seed(seed)
        self.version = 0

    def snapshot(self) -> PolicySnapshot:
        return capture_snapshot(self.network, self.normalizer, self.version, self.value_scale())

    def value_scale(self) -> tuple[float, float] | None:
        """The (mean, std) that turn the critic's standardised outputs into values (None: ``normalize_values`` off)."""
        if self.value_statistics is None:
            return None
        return float(self.value_statistics.mean[0]), float(np.sqrt(self.value_statistics.var[0] + NORMALIZER_EPSILON))

    def _fold_in_value_targets(self, returns: torch.Tensor) -> tuple[float, float]:
        """Add a batch's value targets to the statistics, rescaling the critic's last layer so that its values
        (mean + std x output) stay what they were; return the new (mean, std). The first batch sets the statistics
        outright: an untrained critic's outputs are not worth keeping, and kept they would start far off their
        standardised targets."""
        assert self.value_statistics is not None
        before = self.value_scale()
        first = self.value_statistics.count == 0
        self.value_statistics.update(returns.numpy()[:, None])
        after = self.value_scale()
        assert before is not None and after is not None
        if first:
            return after
        (old_mean, old_std), (new_mean, new_std) = before, after
        last = self.network.critic[-1]
        assert isinstance(last, nn.Linear)
        with torch.no_grad():
            last.weight.mul_(old_std / new_std)
            last.bias.mul_(old_std).add_(old_mean - new_mean).div_(new_std)
        return after

    def update(
        self, batches: Sequence[TrajectoryBatch], progress: float = 0.0, max_policy_lag: int = 0
    ) -> dict[str, float]:
        """One PPO update on batches collected with the current snapshot, or one at most ``max_policy_lag``
        updates older: the ratio is taken against the log-probabilities of the policy that acted.

        ``progress`` in [0, 1] is the share of the step budget already spent (learning-rate annealing).
        Steps the batches mark ``score_only`` are left out, normaliser statistics included (their
        advantages are computed with the rest: no advantage chain crosses an episode's end); where every
        step is, the policy stays as it was and the losses read NaN. A critic that reads the task reads each
        step's from the batch's ``critic_tasks``.
        """
        accepted = range(self.version - max_policy_lag, self.version + 1)
        stale = sorted({batch.policy_version for batch in batches if batch.policy_version not in accepted})
        if stale:
            raise ValueError(
                f"PPO is near on-policy: batches of policy version(s) {stale}, learner at {self.version}, "
                f"at most {max_policy_lag} behind accepted"
            )
        cfg = self.config
        learning_rate = annealed_learning_rate(cfg, progress)
        for group in self.optimizer.param_groups:
            group["lr"] = learning_rate

        gae = [compute_advantages(batch, cfg.gamma, cfg.gae_lambda) for batch in batches]
        raw_observations = np.concatenate([b.observations.reshape(-1, b.observations.shape[-1]) for b in batches])
        actions_array = np.concatenate([b.actions.reshape(-1, b.actions.shape[-1]) for b in batches])
        old_log_probs = _flat(b.log_probs for b in batches)
        old_values = _flat(b.values for b in batches)
        advantages = _flat(adv for adv, _ in gae)
        returns = _flat(ret for _, ret in gae)
        tasks_array = _critic_tasks(batches, self.network.spec.critic_task_dim)
        kept = _trained_steps(batches)
        if kept is not None:  # robust PLR: a score-only episode's steps stay out of the update, normaliser included
            raw_observations, actions_array = raw_observations[kept], actions_array[kept]
            tasks_array = None if tasks_array is None else tasks_array[kept]
            index = torch.from_numpy(kept)
            old_log_probs, old_values = old_log_probs[index], old_values[index]
            advantages, returns = advantages[index], returns[index]
        features = self.features(raw_observations)
        normalizes = self.network.spec.normalizes_observations
        inputs = self.normalizer.normalize(features) if normalizes else features.astype(np.float32, copy=False)
        observations = torch.from_numpy(inputs)
        actions = torch.from_numpy(actions_array)
        critic_tasks = None if tasks_array is None else torch.from_numpy(tasks_array)

        size = observations.shape[0]
        stats: dict[str, list[torch.Tensor]] = {
            name: [] for name in ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction")
        }
        if size == 0:  # every step score-only (robust PLR exploring new levels): the policy stays as it was
            return {**{name: float("nan") for name in stats}, "learning_rate": learning_rate}
        value_targets, value_baseline = returns, old_values  # what the critic's outputs are compared with
        if self.value_statistics is not None:
            mean, std = self._fold_in_value_targets(returns)
            value_targets, value_baseline = (returns - mean) / std, (old_values - mean) / std
        for _ in range(cfg.update_epochs):
            order = torch.randperm(size, generator=self.shuffle)
            for start in range(0, size, cfg.minibatch_size):
                idx = order[start : start + cfg.minibatch_size]
                new_log_probs, entropy, new_values = self.network.evaluate(
                    observations[idx], actions[idx], None if critic_tasks is None else critic_tasks[idx]
                )
                losses = ppo_losses(
                    new_log_probs,
                    old_log_probs[idx],
                    advantages[idx],
                    new_values,
                    value_baseline[idx],
                    value_targets[idx],
                    entropy,
                    cfg,
                )
                self.optimizer.zero_grad()
                losses.total.backward()  # type: ignore[no-untyped-call]  # torch leaves Tensor.backward unannotated
                nn.utils.clip_grad_norm_(self.network.parameters(), cfg.max_grad_norm)
                self.optimizer.step()
                self.network.floor_log_std()

                for name in stats:
                    stats[name].append(getattr(losses, name).detach())
            if cfg.target_kl is not None and losses.approx_kl.item() > cfg.target_kl:
                break

        if normalizes:
            self.normalizer.update(features)
        self.version += 1
        metrics = {name: torch.stack(values).mean().item() for name, values in stats.items()}
        metrics["learning_rate"] = learning_rate
        metrics["explained_variance"] = _explained_variance(old_values.numpy(), returns.numpy())
        if self.network.spec.categorical:  # no std; its entropy is the spread to watch
            return metrics
        with torch.no_grad():  # a shared log-std needs no pass over the batch; a per-state one is averaged over it
            if self.network.spec.state_dependent_std:
                log_std = self.network.mean_and_log_std(observations)[1]
            else:
                log_std = self.network.actor_log_std
            metrics["action_std"] = float(log_std.exp().mean().item())
        return metrics

    def state_dict(self) -> dict[str, Any]:
        state = {
            "network": self.network.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "normalizer": _tensors(self.normalizer),
            "shuffle_rng": self.shuffle.get_state(),
            "version": self.version,
        }
        if self.value_statistics is not None:
            state["value_statistics"] = _tensors(self.value_statistics)
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Everything a resumed run continues from; an evaluation-only checkpoint's state, which has no
        optimiser state, raises ``EvaluationOnlyCheckpointError``."""
        if missing := [name for name in RESUME_ONLY_STATE if name not in state]:
            raise EvaluationOnlyCheckpointError(
                f"the learner state has no {' or '.join(missing)}: an evaluation-only checkpoint, whose policy "
                "can be evaluated and rendered but from which training cannot resume"
            )
        self.load_policy_state(state)
        self.optimizer.load_state_dict(state["optimizer"])
        self.shuffle.set_state(state["shuffle_rng"])

    def load_policy_state(self, state: dict[str, Any]) -> None:
        """The policy alone (network, normaliser, value statistics and version), as evaluation reads it; no
        optimiser state needed. A state without value statistics starts them afresh under ``normalize_values``;
        one with them needs it (its critic's outputs are standardised)."""
        if "value_statistics" in state and self.value_statistics is None:
            raise ValueError("this learner state's critic learned standardised values: it needs normalize_values")
        self.network.load_state_dict(state["network"])
        _load(self.normalizer, state["normalizer"])
        if self.value_statistics is not None and "value_statistics" in state:
            _load(self.value_statistics, state["value_statistics"])
        self.version = int(state["version"])


def _tensors(normalizer: RunningNormalizer) -> dict[str, torch.Tensor]:
    """A normaliser's statistics as a checkpoint holds them."""
    return {name: torch.as_tensor(value) for name, value in vars(normalizer.state()).items()}


def _load(normalizer: RunningNormalizer, saved: dict[str, Any]) -> None:
    restored = {name: np.asarray(value) for name, value in saved.items()}
    normalizer.load_state(NormalizerState(**restored))  # type: ignore[arg-type]  # count: a 0-d array, used as a float


def _critic_tasks(batches: Sequence[TrajectoryBatch], width: int) -> np.ndarray | None:
    """Every step's task inputs, flat (steps, width), for a critic that reads ``width`` of them (else None)."""
    if not width:
        return None
    tasks = [batch.critic_tasks for batch in batches]
    if any(part is None or part.shape[-1] != width for part in tasks):
        raise ValueError(f"the critic reads {width} task inputs per step, and a batch carries none or another width")
    return np.concatenate([part.reshape(-1, width) for part in tasks if part is not None])


def _trained_steps(batches: Sequence[TrajectoryBatch]) -> np.ndarray | None:
    """The flat indices of the steps to update on, in order, or None for all of them (no score-only step)."""
    marks = [batch.score_only for batch in batches]
    if not any(mark is not None and mark.any() for mark in marks):
        return None
    flat = np.concatenate(
        [
            np.zeros(b.rewards.size, dtype=bool) if m is None else m.reshape(-1)
            for b, m in zip(batches, marks, strict=True)
        ]
    )
    return np.flatnonzero(~flat)


def _flat(arrays: Any) -> torch.Tensor:
    return torch.from_numpy(np.concatenate([np.asarray(a, dtype=np.float32).reshape(-1) for a in arrays]))


def _explained_variance(predicted: np.ndarray, target: np.ndarray) -> float:
    """1 = the critic predicts the returns perfectly, 0 = no better than their mean."""
    variance = float(np.var(target))
    return float("nan") if variance == 0 else 1.0 - float(np.var(target - predicted)) / variance
