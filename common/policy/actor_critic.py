"""The actor-critic network the learner trains, and how its layers are read out for the workers.

A Gaussian policy whose log standard deviation is one learned number per action dimension, or, with
``PolicySpec.state_dependent_std``, a second output of the actor's head; actions are sampled unbounded
and clipped to the action box by whoever steps the environment, so log-probabilities stay exact. With
``PolicySpec.categorical`` (a ``Discrete`` action space, MiniGrid's) the actor's head gives one logit per
action instead, and an action is a choice among them, carried as its index. With ``PolicySpec.image_shape``
each head starts with a small CNN (``image_encoder``) on the image's pixels.
Workers only ever see a ``PolicySnapshot`` (plain numpy, cheap to put in Ray's object store): the
network's layers as read from its modules, in order. They run it through ``InferencePolicy``, which
prepares observations as in training (angles become (sin, cos) features, ``ObservationFeatures``,
then the normaliser's statistics apply, except to an image's pixels) and runs those layers in numpy.
Those live in ``common.policy.inference``, which needs no torch, and are imported here under their usual
names.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import torch
from torch import nn

from common.policy.inference import (
    LOG_SQRT_2PI,
    PIXEL_SCALE,
    Activation,
    ConvLayer,
    DenseLayer,
    ImageInputLayer,
    Layer,
    flatten_channels_first,
    relu,
)
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


class ImageInput(nn.Module):
    """Flat observations, images flattened in (height, width, channels) order with pixels 0..255, to the
    (n, channels, height, width) batch of pixels in [0, 1] that ``nn.Conv2d`` reads."""

    def __init__(self, shape: tuple[int, int, int]) -> None:
        super().__init__()
        self.shape = shape

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return (observations * PIXEL_SCALE).reshape(-1, *self.shape).permute(0, 3, 1, 2)


ENCODER_CHANNELS = (16, 32)
"""Filters of the image encoder's 3x3 convolutions, in order."""
STRIDE_2_FROM = 16
"""A convolution halves its input where the input's smaller side is at least this."""


def image_encoder(shape: tuple[int, int, int]) -> tuple[list[nn.Module], int]:
    """A small CNN for one head, and the width of its flat output: 3x3 convolutions of 16 then 32 filters
    with ReLUs, no padding, each with stride 2 where its input is at least 16 pixels a side. Small images
    keep their resolution (MiniGrid's 7 x 7 view: 5 x 5, then 3 x 3 x 32 = 288 features) and large ones
    stay cheap on a CPU (64 x 64: 31 x 31, then 15 x 15 x 32 = 7,200)."""
    height, width, channels = shape
    modules: list[nn.Module] = [ImageInput(shape)]
    for filters in ENCODER_CHANNELS:
        stride = 2 if min(height, width) >= STRIDE_2_FROM else 1
        convolution = nn.Conv2d(channels, filters, kernel_size=3, stride=stride)
        nn.init.orthogonal_(convolution.weight, np.sqrt(2))
        nn.init.zeros_(convolution.bias)  # type: ignore[arg-type]  # Conv2d made with bias=True has one
        modules += [convolution, nn.ReLU()]
        height, width, channels = (height - 3) // stride + 1, (width - 3) // stride + 1, filters
    return [*modules, nn.Flatten()], height * width * channels


def _head(spec: PolicySpec, outputs: int, output_gain: float, task_dim: int = 0) -> nn.Sequential:
    """A head's network: a tanh MLP on the features (and ``task_dim`` task inputs after them), or, for an image,
    on its own ``image_encoder``'s output."""
    if spec.image_shape is None:
        return _mlp([spec.feature_dim + task_dim, *spec.hidden_sizes, outputs], output_gain)
    encoder, width = image_encoder(spec.image_shape)
    return nn.Sequential(*encoder, *_mlp([width, *spec.hidden_sizes, outputs], output_gain))


class ActorCritic(nn.Module):
    """Separate tanh MLPs for the action mean and the value (sharing hurts PPO on control tasks).

    For an image each head has its own encoder too, which keeps the heads separate networks as they are for
    vectors: no value loss pulling on the actor's features, no weighting of the two losses in one encoder,
    and the numpy side's heads stay independent stacks of layers. The price is twice the convolutions, small
    beside an environment step at these sizes.

    With a state-dependent std the actor's head has twice the outputs, the mean's then the log-std's;
    the latter start at ``init_log_std`` in every state (zero bias offset, near-zero weights), and
    ``actor_log_std`` does not exist. With ``PolicySpec.critic_task_dim`` the critic also reads the episode's
    task after the features (asymmetric actor-critic, Pinto et al. 2018): the value of a state depends on the
    task the teacher set, which the actor, the part that is deployed, never needs.
    """

    def __init__(self, spec: PolicySpec) -> None:
        super().__init__()
        self.spec = spec
        outputs = 2 * spec.action_dim if spec.state_dependent_std else spec.action_dim
        self.actor_mean = _head(spec, outputs, output_gain=0.01)
        """The Gaussian's means (and per-state log-stds), or a categorical policy's logits, near uniform at first."""
        self.critic = _head(spec, 1, output_gain=1.0, task_dim=spec.critic_task_dim)
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

    def value(self, observations: torch.Tensor, critic_tasks: torch.Tensor | None = None) -> torch.Tensor:
        """Values (n,) of normalised observations, with their tasks (n, critic_task_dim) where the critic reads them."""
        if self.spec.critic_task_dim:
            if critic_tasks is None:
                raise ValueError("this critic reads the task: pass each observation's critic_tasks")
            observations = torch.cat([observations, critic_tasks], dim=-1)
        values: torch.Tensor = self.critic(observations)
        return values.squeeze(-1)

    def evaluate(
        self, observations: torch.Tensor, actions: torch.Tensor, critic_tasks: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Return (log-probability, entropy, value) of given actions, with gradients; a categorical policy's
        actions are (n, 1) indices as floats; ``critic_tasks`` as for ``value``."""
        values = self.value(observations, critic_tasks)
        if self.spec.categorical:
            log_probs = torch.log_softmax(self.actor_mean(observations), dim=-1)
            chosen = log_probs.gather(-1, actions.long()).squeeze(-1)
            entropy = -(log_probs.exp() * log_probs).sum(-1)
            return chosen, entropy, values
        mean, log_std = self.mean_and_log_std(observations)
        entropy = (0.5 + LOG_SQRT_2PI + log_std).sum(-1).expand(mean.shape[0])
        return self._log_prob(mean, log_std, actions), entropy, values

    @staticmethod
    def _log_prob(mean: torch.Tensor, log_std: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Diagonal Gaussian log-density, summed over action dimensions."""
        return (-0.5 * ((actions - mean) / log_std.exp()) ** 2 - log_std - LOG_SQRT_2PI).sum(-1)


NUMPY_ACTIVATIONS: dict[type[nn.Module], Activation] = {nn.Tanh: np.tanh, nn.ReLU: relu}
"""The activation modules ``InferencePolicy`` can run, each with the numpy function that does its work."""


def head_layers(head: nn.Module) -> tuple[Layer, ...]:
    """The head's layers as numpy, in the order its forward pass runs them, read from the module itself.

    A head is an ``nn.Linear`` or an ``nn.Sequential`` (nested ones included) of ``nn.Linear`` and
    activations from ``NUMPY_ACTIVATIONS``, starting with a Linear; or, on images, an ``ImageInput``, then
    ``nn.Conv2d`` without padding, dilation or groups, with activations, then ``nn.Flatten``, then
    such a dense stack. Anything else raises ``TypeError`` here, when the policy is captured, rather than
    acting differently from the network.
    """
    layers: list[Layer] = []
    images = False
    """Whether the layers so far output images rather than flat features."""
    for module in _in_order(head):
        if isinstance(module, ImageInput) and not layers:
            layers.append(ImageInputLayer(module.shape))
            images = True
        elif isinstance(module, nn.Conv2d) and images and _plain_convolution(module):
            bias = np.zeros(module.out_channels) if module.bias is None else numpy_copy(module.bias)
            stride = (module.stride[0], module.stride[1])
            layers.append(ConvLayer(numpy_copy(module.weight), bias, stride, ()))
        elif isinstance(module, nn.Flatten) and images and isinstance(layers[-1], ConvLayer):
            if (module.start_dim, module.end_dim) != (1, -1):
                raise TypeError(f"InferencePolicy cannot run {module!r}: it flattens whole images only")
            _append_activation(layers, flatten_channels_first)
            images = False
        elif isinstance(module, nn.Linear) and not images:
            bias = np.zeros(module.out_features) if module.bias is None else numpy_copy(module.bias)
            layers.append(DenseLayer(numpy_copy(module.weight), bias, ()))
        elif type(module) in NUMPY_ACTIVATIONS and layers and not isinstance(layers[-1], ImageInputLayer):
            _append_activation(layers, NUMPY_ACTIVATIONS[type(module)])
        else:
            raise TypeError(
                f"InferencePolicy cannot run {module!r} here: a head must start with nn.Linear, or with ImageInput "
                "then nn.Conv2d (no padding, dilation or groups) and nn.Flatten before its first nn.Linear, and "
                f"hold only those and {', '.join(kind.__name__ for kind in NUMPY_ACTIVATIONS)} (add a numpy "
                "counterpart to NUMPY_ACTIVATIONS)"
            )
    return tuple(layers)


def _plain_convolution(module: nn.Conv2d) -> bool:
    """Whether ``ConvLayer`` describes the convolution: no padding, no dilation, one group."""
    return module.padding in ((0, 0), "valid") and module.dilation == (1, 1) and module.groups == 1


def _append_activation(layers: list[Layer], activation: Activation) -> None:
    last = layers[-1]
    assert not isinstance(last, ImageInputLayer)
    layers[-1] = replace(last, activations=(*last.activations, activation))


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


def capture_snapshot(
    network: ActorCritic, normalizer: RunningNormalizer, version: int, value_scale: tuple[float, float] | None = None
) -> PolicySnapshot:
    """The network's current layers and the normaliser's statistics as plain numpy, for the rollout
    workers (the learner's side: the one step from torch to a ``PolicySnapshot``). ``value_scale`` (mean,
    std): the critic outputs standardised values, and its last layer is rescaled here so that the workers'
    values come out on the returns' scale, as GAE and the episodes' scores need them."""
    critic = head_layers(network.critic)
    if value_scale is not None:
        mean, std = value_scale
        last = critic[-1]
        assert isinstance(last, DenseLayer) and not last.activations, "a critic ends in a plain linear layer"
        critic = (*critic[:-1], replace(last, weight=last.weight * std, bias=last.bias * std + mean))
    return PolicySnapshot(
        network.spec,
        head_layers(network.actor_mean),
        critic,
        None if network.spec.state_dependent_std or network.spec.categorical else numpy_copy(network.actor_log_std),
        normalizer.state(),
        normalizer.clip,
        version,
    )
