"""The actor-critic network the learner trains, and how its layers are read out for the workers.

A Gaussian policy whose log standard deviation is one learned number per action dimension, or, with
``PolicySpec.state_dependent_std``, a second output of the actor's head; actions are sampled unbounded
and clipped to the action box by whoever steps the environment, so log-probabilities stay exact. With
``PolicySpec.categorical`` (a ``Discrete`` action space, MiniGrid's) the actor's head gives one logit per
action instead, and an action is a choice among them, carried as its index.
Workers only ever see a ``PolicySnapshot`` (plain numpy, cheap to put in Ray's object store): the
network's layers as read from its modules, in order. They run it through ``InferencePolicy``, which
prepares observations as in training (angles become (sin, cos) features, ``ObservationFeatures``,
then the normaliser's statistics apply) and runs those layers in numpy. Those live in
``common.policy.inference``, which needs no torch, and are imported here under their usual names.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import replace

import numpy as np
import torch
from torch import nn

from common.policy.inference import LOG_SQRT_2PI, DenseLayer
from common.policy.inference import InferencePolicy as InferencePolicy
from common.policy.inference import ObservationFeatures as ObservationFeatures
from common.policy.inference import PolicySnapshot as PolicySnapshot
from common.policy.inference import PolicySpec as PolicySpec
from common.policy.normalizer import RunningNormalizer


def _layer(in_features: int, out_features: int, gain: float) -> nn.Linear:
    layer = nn.Linear(in_features, out_features)
    nn.init.orthogonal_(layer.weight, gain)
    nn.init.zeros_(layer.bias)
    return layer


def _mlp(sizes: list[int], output_gain: float) -> nn.Sequential:
    layers: list[nn.Module] = []
    for in_features, out_features in zip(sizes[:-2], sizes[1:-1], strict=True):
        layers += [_layer(in_features, out_features, np.sqrt(2)), nn.Tanh()]
    layers.append(_layer(sizes[-2], sizes[-1], output_gain))
    return nn.Sequential(*layers)


class ActorCritic(nn.Module):
    """Separate tanh MLPs for the action mean and the value (sharing hurts PPO on control tasks).

    With a state-dependent std the actor's head has twice the outputs, the mean's then the log-std's;
    the latter start at ``init_log_std`` in every state (zero bias offset, near-zero weights), and
    ``actor_log_std`` does not exist.
    """

    def __init__(self, spec: PolicySpec) -> None:
        super().__init__()
        self.spec = spec
        hidden = list(spec.hidden_sizes)
        outputs = 2 * spec.action_dim if spec.state_dependent_std else spec.action_dim
        self.actor_mean = _mlp([spec.feature_dim, *hidden, outputs], output_gain=0.01)
        """The Gaussian's means (and per-state log-stds), or a categorical policy's logits, near uniform at first."""
        self.critic = _mlp([spec.feature_dim, *hidden, 1], output_gain=1.0)
        if spec.categorical:
            return
        if spec.state_dependent_std:
            last = self.actor_mean[-1]
            assert isinstance(last, nn.Linear)
            nn.init.constant_(last.bias[spec.action_dim :], spec.init_log_std)
        else:
            self.actor_log_std = nn.Parameter(torch.full((spec.action_dim,), float(spec.init_log_std)))

    def mean_and_log_std(self, observations: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Action means (n, action_dim) and log-stds: (n, action_dim) per state, or (action_dim,) shared."""
        output: torch.Tensor = self.actor_mean(observations)
        if not self.spec.state_dependent_std:
            return output, self.actor_log_std
        low, high = self.spec.log_std_range
        return output[:, : self.spec.action_dim], output[:, self.spec.action_dim :].clamp(low, high)

    def floor_log_std(self) -> None:
        """Project a shared log-std back onto ``min_log_std`` after an optimiser step. A clamp in the
        forward pass would cut its gradient, and one pushed under the floor could never come back."""
        if not self.spec.categorical and not self.spec.state_dependent_std and self.spec.min_log_std is not None:
            with torch.no_grad():
                self.actor_log_std.clamp_(min=self.spec.min_log_std)

    def value(self, observations: torch.Tensor) -> torch.Tensor:
        values: torch.Tensor = self.critic(observations)
        return values.squeeze(-1)

    def evaluate(
        self, observations: torch.Tensor, actions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Return (log-probability, entropy, value) of given actions, with gradients; a categorical policy's
        actions are (n, 1) indices as floats."""
        if self.spec.categorical:
            log_probs = torch.log_softmax(self.actor_mean(observations), dim=-1)
            chosen = log_probs.gather(-1, actions.long()).squeeze(-1)
            entropy = -(log_probs.exp() * log_probs).sum(-1)
            return chosen, entropy, self.value(observations)
        mean, log_std = self.mean_and_log_std(observations)
        entropy = (0.5 + LOG_SQRT_2PI + log_std).sum(-1).expand(mean.shape[0])
        return self._log_prob(mean, log_std, actions), entropy, self.value(observations)

    @staticmethod
    def _log_prob(mean: torch.Tensor, log_std: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Diagonal Gaussian log-density, summed over action dimensions."""
        return (-0.5 * ((actions - mean) / log_std.exp()) ** 2 - log_std - LOG_SQRT_2PI).sum(-1)


NUMPY_ACTIVATIONS: dict[type[nn.Module], Callable[[np.ndarray], np.ndarray]] = {nn.Tanh: np.tanh}
"""The activation modules ``InferencePolicy`` can run, each with the numpy function that does its work."""


def dense_layers(head: nn.Module) -> tuple[DenseLayer, ...]:
    """The head's layers as numpy, in the order its forward pass runs them, read from the module itself.

    A head is an ``nn.Linear`` or an ``nn.Sequential`` (nested ones included) of ``nn.Linear`` and
    activations from ``NUMPY_ACTIVATIONS``, starting with a Linear. Anything else raises
    ``TypeError`` here, when the policy is captured, rather than acting differently from the network.
    """
    layers: list[DenseLayer] = []
    for module in _in_order(head):
        if isinstance(module, nn.Linear):
            bias = np.zeros(module.out_features) if module.bias is None else numpy_copy(module.bias)
            layers.append(DenseLayer(numpy_copy(module.weight), bias, ()))
        elif type(module) in NUMPY_ACTIVATIONS and layers:
            last = layers[-1]
            layers[-1] = replace(last, activations=(*last.activations, NUMPY_ACTIVATIONS[type(module)]))
        else:
            raise TypeError(
                f"InferencePolicy cannot run {module!r}: a head must start with nn.Linear and hold only nn.Linear "
                f"and {', '.join(kind.__name__ for kind in NUMPY_ACTIVATIONS)} (add a numpy counterpart to "
                "NUMPY_ACTIVATIONS)"
            )
    return tuple(layers)


def _in_order(module: nn.Module) -> Iterator[nn.Module]:
    """The modules a forward pass runs, in order: ``nn.Sequential`` containers are opened, anything else kept."""
    if isinstance(module, nn.Sequential):
        for child in module:
            yield from _in_order(child)
    else:
        yield module


def numpy_copy(tensor: torch.Tensor) -> np.ndarray:
    """A tensor's values as a numpy array of their own (not sharing the parameter's memory)."""
    array: np.ndarray = tensor.detach().cpu().numpy().copy()
    return array


def capture_snapshot(network: ActorCritic, normalizer: RunningNormalizer, version: int) -> PolicySnapshot:
    """The network's current layers and the normaliser's statistics as plain numpy, for the rollout
    workers (the learner's side: the one step from torch to a ``PolicySnapshot``)."""
    return PolicySnapshot(
        network.spec,
        dense_layers(network.actor_mean),
        dense_layers(network.critic),
        None if network.spec.state_dependent_std or network.spec.categorical else numpy_copy(network.actor_log_std),
        normalizer.state(),
        normalizer.clip,
        version,
    )
