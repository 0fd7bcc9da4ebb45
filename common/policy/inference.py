"""The policy as the rollout workers run it: its shape, its snapshot and numpy inference, without torch.

A worker process imports only this side of the policy (``actor_critic`` holds the torch network the
learner trains), so a worker starts without loading torch: at start-up that import is most of a
worker's time before its first step. ``actor_critic.capture_snapshot`` reads a network's layers on the
learner's side and is the one function here that needs torch, which it imports when called.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import TypeGuard

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from common.policy.noise import LOG_STD_BOUNDS
from common.policy.normalizer import NORMALIZER_EPSILON, NormalizerState


@dataclass(frozen=True)
class WorldOffset:
    """An observed planar vector given in a body's frame, and that body's observed Euler angles (roll about
    x, then pitch about y, then yaw about z, as pybullet reports them): the networks also get the vector's
    (x, y) in the world frame. A network that must act in the world frame on a vector it sees in a turning
    frame otherwise has to learn the rotation, a product of inputs a small tanh MLP fits only roughly."""

    x_index: int
    y_index: int
    euler_indices: tuple[int, int, int]

    @property
    def indices(self) -> tuple[int, ...]:
        return (self.x_index, self.y_index, *self.euler_indices)


MIN_IMAGE_SIDE = 5
"""The smallest image side ``actor_critic.image_encoder`` takes: its two 3x3 convolutions without padding
each take 2 pixels off a side."""

PIXEL_SCALE = 1.0 / 255.0
"""What both sides multiply pixels by before the first convolution."""


@dataclass(frozen=True)
class PolicySpec:
    """Everything needed to rebuild the network's shape on another process."""

    obs_dim: int
    action_dim: int
    hidden_sizes: tuple[int, ...] = (64, 64)
    init_log_std: float = -0.5
    angle_indices: tuple[int, ...] = ()
    """Observation entries that are angles in [-pi, pi]; the networks see each as (sin, cos)."""
    state_dependent_std: bool = False
    """The actor's head outputs the log-std per state (clamped to ``LOG_STD_BOUNDS``) beside the mean."""
    min_log_std: float | None = None
    """Floor of the log-std (None = none beyond ``LOG_STD_BOUNDS`` for a state-dependent one)."""
    world_offsets: tuple[WorldOffset, ...] = ()
    """Observed vectors whose world-frame (x, y) the networks also see, after the other features."""
    half_turn_indices: tuple[int, ...] = ()
    """Angles among ``angle_indices`` of something that looks the same turned half a turn (a box's yaw): the
    networks see (sin 2a, cos 2a), so both readings of one pose are one input."""
    categorical: bool = False
    """Actions are one of ``action_dim`` choices (gymnasium's ``Discrete(action_dim)``), drawn from a categorical
    distribution over the actor head's ``action_dim`` logits; batches carry each as its index, one float per
    step. The log-std options do not apply. False: a Gaussian over a box of ``action_dim`` dimensions."""
    image_shape: tuple[int, int, int] | None = None
    """(height, width, channels) of an image observation (pixels 0..255), which arrives flattened in row-major
    (height, width, channels) order, ``image.reshape(-1)``, as float32: each network then starts with a small
    CNN (``actor_critic.image_encoder``) and the observation normaliser is not applied. None: a flat vector."""
    critic_task_dim: int = 0
    """Width of the episode's task, in [0, 1] per parameter, that the critic reads after the observation's
    features (asymmetric actor-critic: the actor never sees it); 0: the critic reads what the actor reads."""

    def __post_init__(self) -> None:
        if self.critic_task_dim < 0:
            raise ValueError(f"critic_task_dim must be 0 or more, got {self.critic_task_dim}")
        if self.image_shape is not None:
            self._check_image()
        if self.categorical and (self.state_dependent_std or self.min_log_std is not None or self.action_dim < 2):
            raise ValueError(
                "a categorical policy needs at least 2 actions and has no log-std "
                f"(state_dependent_std, min_log_std), got {self}"
            )
        if self.min_log_std is not None and not LOG_STD_BOUNDS[0] <= self.min_log_std < LOG_STD_BOUNDS[1]:
            low, high = LOG_STD_BOUNDS
            raise ValueError(f"min_log_std must be in [{low}, {high}), got {self.min_log_std}")
        if not self._distinct_entries(self.angle_indices):
            raise ValueError(
                f"angle_indices must be distinct observation indices below {self.obs_dim}, got {self.angle_indices}"
            )
        for offset in self.world_offsets:
            if not self._distinct_entries(offset.indices):
                raise ValueError(
                    f"a world offset must name 5 distinct observation indices below {self.obs_dim}, got {offset}"
                )
        if not self._distinct_entries(self.half_turn_indices) or not set(self.half_turn_indices) <= set(
            self.angle_indices
        ):
            raise ValueError(
                f"half_turn_indices must be distinct entries of angle_indices {self.angle_indices}, "
                f"got {self.half_turn_indices}"
            )

    def _check_image(self) -> None:
        """An image is the whole observation, and pixels are no angles or offsets."""
        assert self.image_shape is not None
        height, width, channels = self.image_shape
        if min(height, width) < MIN_IMAGE_SIDE or channels < 1 or self.obs_dim != height * width * channels:
            raise ValueError(
                f"image_shape must be (height, width, channels), each side at least {MIN_IMAGE_SIDE}, with "
                f"obs_dim = height * width * channels, got {self.image_shape} for obs_dim {self.obs_dim}"
            )
        if self.angle_indices or self.world_offsets or self.half_turn_indices:
            raise ValueError(
                "an image observation has no angle_indices, world_offsets or half_turn_indices, "
                f"got {self.angle_indices}, {self.world_offsets}, {self.half_turn_indices}"
            )
        if self.critic_task_dim:
            raise ValueError(
                "a critic that reads the task needs a flat observation: its task joins the features an MLP reads, "
                f"and an image's critic starts with convolutions (critic_task_dim {self.critic_task_dim})"
            )

    def _distinct_entries(self, indices: tuple[int, ...]) -> bool:
        """Whether ``indices`` name distinct entries of an observation."""
        return len(set(indices)) == len(indices) and all(0 <= index < self.obs_dim for index in indices)

    @property
    def feature_dim(self) -> int:
        """Width of the networks' input: every angle becomes two features, every world offset adds two."""
        return self.obs_dim + len(self.angle_indices) + 2 * len(self.world_offsets)

    @property
    def critic_input_dim(self) -> int:
        """Width of the critic's input: the features, then the task where the critic reads it."""
        return self.feature_dim + self.critic_task_dim

    @property
    def normalizes_observations(self) -> bool:
        """Whether the running normaliser scales the networks' inputs: not an image's, whose encoder scales its
        pixels by a fixed 1/255 (per-pixel statistics would make a rare bright pixel huge). The learner and
        ``InferencePolicy`` both ask here."""
        return self.image_shape is None

    @property
    def log_std_range(self) -> tuple[float, float]:
        """Where a state-dependent log-std is clamped: ``LOG_STD_BOUNDS``, raised to ``min_log_std``."""
        low, high = LOG_STD_BOUNDS
        return (low if self.min_log_std is None else max(low, self.min_log_std)), high


class ObservationFeatures:
    """Raw observations to network inputs: angles as (sin, cos) (half-turn angles doubled first),
    everything else unchanged, then each of the spec's world offsets as its world-frame (x, y).

    An angle near +-pi (the gripper's roll, pointing down, flips sign from one step to the next)
    is a jump of 2 pi to a network fed the raw number, and a normaliser turns it into noise of
    unit size; on the circle it is no jump at all.
    """

    def __init__(self, spec: PolicySpec) -> None:
        angles = set(spec.angle_indices)
        self._plain = [index for index in range(spec.obs_dim) if index not in angles]
        self._angles = list(spec.angle_indices)
        half_turns = set(spec.half_turn_indices)
        self._angle_multipliers = (
            np.array([2.0 if index in half_turns else 1.0 for index in spec.angle_indices], dtype=np.float32)
            if half_turns
            else None
        )
        self._world_offsets = spec.world_offsets

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        if not self._angles and not self._world_offsets:
            return observations
        parts = [observations[..., self._plain]]
        if self._angles:
            angles = observations[..., self._angles]
            if self._angle_multipliers is not None:
                angles = angles * self._angle_multipliers
            parts += [np.sin(angles), np.cos(angles)]
        parts += [_in_world_frame(observations, offset) for offset in self._world_offsets]
        return np.concatenate(parts, axis=-1)


def _in_world_frame(observations: np.ndarray, offset: WorldOffset) -> np.ndarray:
    """The offset's vector (x, y, 0) turned by R = Rz(yaw) Ry(pitch) Rx(roll), its world x and y: (..., 2)."""
    x, y = observations[..., offset.x_index], observations[..., offset.y_index]
    roll, pitch, yaw = (observations[..., index] for index in offset.euler_indices)
    cos_pitch, sin_pitch = np.cos(pitch), np.sin(pitch)
    cos_roll, sin_roll = np.cos(roll), np.sin(roll)
    cos_yaw, sin_yaw = np.cos(yaw), np.sin(yaw)
    world_x = cos_yaw * cos_pitch * x + (cos_yaw * sin_pitch * sin_roll - sin_yaw * cos_roll) * y
    world_y = sin_yaw * cos_pitch * x + (sin_yaw * sin_pitch * sin_roll + cos_yaw * cos_roll) * y
    return np.stack([world_x, world_y], axis=-1)


LOG_SQRT_2PI = 0.5 * math.log(2 * math.pi)
_LOG_SQRT_2PI_FLOAT32 = np.float32(LOG_SQRT_2PI)


Activation = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class DenseLayer:
    """One ``nn.Linear`` of a network head as numpy, with the activations the head applies after it."""

    weight: np.ndarray
    """(out_features, in_features), as torch stores it."""
    bias: np.ndarray
    activations: tuple[Activation, ...]


@dataclass(frozen=True)
class ImageInputLayer:
    """What ``actor_critic.ImageInput`` does, a head's first step on image observations: flat observations
    to images (n, height, width, channels) of pixels times ``PIXEL_SCALE``. Numpy keeps the channels last,
    where torch moves them first: a patch of a channels-last image is one strided view (``ConvLayer``)."""

    shape: tuple[int, int, int]
    """(height, width, channels)."""


@dataclass(frozen=True)
class ConvLayer:
    """One ``nn.Conv2d`` (no padding, no dilation, one group) of a head's image encoder as numpy, with the
    activations after it; ``flatten_channels_first`` among them is the encoder's ``nn.Flatten``."""

    weight: np.ndarray
    """(out_channels, in_channels, kernel_height, kernel_width), as torch stores it."""
    bias: np.ndarray
    stride: tuple[int, int]
    activations: tuple[Activation, ...]


Layer = ImageInputLayer | ConvLayer | DenseLayer


def relu(hidden: np.ndarray) -> np.ndarray:
    """``nn.ReLU``'s work, a module-level function so that snapshots holding it pickle."""
    rectified: np.ndarray = np.maximum(hidden, np.float32(0.0))
    return rectified


def flatten_channels_first(images: np.ndarray) -> np.ndarray:
    """``nn.Flatten``'s work on channels-last images (n, h, w, c): each image's values in torch's
    (c, h, w) order, which the next layer's weights were trained to read."""
    flat: np.ndarray = images.transpose(0, 3, 1, 2).reshape(len(images), -1)
    return flat


@dataclass(frozen=True)
class PolicySnapshot:
    """The layers and normaliser statistics of one policy version, as plain numpy."""

    spec: PolicySpec
    actor: tuple[Layer, ...]
    """The action mean's head (and the log-std's, its second half of outputs, where that is per state): an
    image spec's starts with its image encoder's layers, ``ImageInputLayer`` and ``ConvLayer``."""
    critic: tuple[Layer, ...]
    """The value's head, shaped like the actor's."""
    log_std: np.ndarray | None
    """The shared log-std; None where the actor's head outputs it per state, and for a categorical policy."""
    normalizer: NormalizerState
    obs_clip: float
    version: int


_Stage = tuple[np.ndarray, np.ndarray, tuple[Activation, ...]]
"""A ``DenseLayer`` ready to run: weight as (in, out) float32, so the layer is one ``x @ w + b``."""

_Head = tuple[list[Activation], list[_Stage]]
"""A head ready to run: its image layers as functions of the batch (none for a flat observation), then its
dense layers as stages."""


class InferencePolicy:
    """Numpy-in, numpy-out policy for stepping environments; no gradients, no torch.

    At the batch sizes of environment stepping (a handful of observations), per-operation overhead,
    not arithmetic, is the cost: a torch call costs several times a numpy one. So the snapshot's
    layers run as numpy; when the actor and critic heads read the same input and have the same shape of
    layers they are fused into one block-diagonal stack when loaded (half the operations), and the
    observation normaliser's scale is precomputed. A critic that reads the task
    (``PolicySpec.critic_task_dim``) takes it, already in [0, 1], after the normalised features, as
    ``ActorCritic.value`` does, and is not fused. An image spec's heads each start with their own
    convolutions, run as im2col (one strided view of every patch) and a matmul, and are not fused. The
    layers are those ``actor_critic.capture_snapshot`` read from the network's modules, so a change to
    ``ActorCritic``'s heads needs no change here; ``ActorCritic.evaluate`` is the reference these numbers
    must match.
    """

    def __init__(self, snapshot: PolicySnapshot, seed: int | None = None) -> None:
        self.spec = snapshot.spec
        self._features = ObservationFeatures(self.spec)
        self._log_std_range = self.spec.log_std_range
        self.rng = np.random.default_rng(seed)
        self.version = -1
        self.load(snapshot)

    def load(self, snapshot: PolicySnapshot) -> None:
        if snapshot.spec != self.spec:
            raise ValueError(f"snapshot is for {snapshot.spec}, this policy is {self.spec}")
        actor, critic = snapshot.actor, snapshot.critic
        fused = _fuse(actor, critic) if _dense_only(actor) and _dense_only(critic) else None
        heads = [fused] if fused is not None else [actor, critic]
        self._heads = [_prepared(head) for head in heads]
        if snapshot.log_std is not None:
            log_std = snapshot.log_std.astype(np.float64)
            self._std = np.exp(log_std).astype(np.float32)
            self._log_density_offset = float((log_std + LOG_SQRT_2PI).sum())
        stats = snapshot.normalizer
        self._obs_mean = np.asarray(stats.mean, dtype=np.float64)
        self._obs_inverse_scale = 1.0 / np.sqrt(np.asarray(stats.var, dtype=np.float64) + NORMALIZER_EPSILON)
        self._obs_clip = snapshot.obs_clip
        self.version = snapshot.version

    def _forward(self, observations: np.ndarray, critic_tasks: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The actor head's outputs (n, action_dim, or twice that with a state-dependent std) and values (n,):
        NaN where the critic reads the task and ``critic_tasks`` is None, so the actor acts alone."""
        if self.spec.normalizes_observations:
            scaled = (self._features(np.atleast_2d(observations)) - self._obs_mean) * self._obs_inverse_scale
            inputs = np.clip(scaled, -self._obs_clip, self._obs_clip).astype(np.float32)
        else:
            inputs = np.atleast_2d(observations).astype(np.float32, copy=False)
        if len(self._heads) == 1:
            output = _run(self._heads[0], inputs)
            return output[:, :-1], output[:, -1]
        actor, critic = self._heads
        actor_output = _run(actor, inputs)
        if not self.spec.critic_task_dim:
            return actor_output, _run(critic, inputs)[:, 0]
        if critic_tasks is None:
            return actor_output, np.full(len(inputs), np.nan, dtype=np.float32)
        tasks = np.atleast_2d(critic_tasks).astype(np.float32, copy=False)
        return actor_output, _run(critic, np.concatenate([inputs, tasks], axis=-1))[:, 0]

    def act(
        self, observations: np.ndarray, deterministic: bool = False, critic_tasks: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (actions, log-probabilities, values) for raw observations of shape (n, obs_dim): actions
        (n, action_dim), or (n, 1) chosen indices as floats for a categorical policy. ``critic_tasks`` (n,
        critic_task_dim) is each episode's task for a critic that reads it; without them such a critic's
        values are NaN (an evaluation acts with the actor alone) and any other ignores them."""
        actor, values = self._forward(observations, critic_tasks)
        if self.spec.categorical:
            return (*self._choose(actor, deterministic), values)
        mean = actor[:, : self.spec.action_dim]
        noise = np.zeros_like(mean) if deterministic else self.rng.standard_normal(mean.shape, dtype=np.float32)
        if self.spec.state_dependent_std:
            log_std = np.clip(actor[:, self.spec.action_dim :], *self._log_std_range)
            std = np.exp(log_std)
            offset = (log_std + _LOG_SQRT_2PI_FLOAT32).sum(axis=-1)
        else:
            std, offset = self._std, self._log_density_offset
        log_probs = (-0.5 * (noise * noise).sum(axis=-1) - offset).astype(np.float32)
        return mean + std * noise, log_probs, values

    def _choose(self, logits: np.ndarray, deterministic: bool) -> tuple[np.ndarray, np.ndarray]:
        """Indices drawn from the categorical distribution of each row of logits (the likeliest one when
        ``deterministic``), as (n, 1) floats, and their log-probabilities (n,): the inverse of each row's
        cumulative distribution at one uniform number, so one draw per row whatever the number of choices."""
        shifted = logits.astype(np.float64) - logits.max(axis=-1, keepdims=True)
        log_probs = shifted - np.log(np.exp(shifted).sum(axis=-1, keepdims=True))
        if deterministic:
            chosen = log_probs.argmax(axis=-1)
        else:
            below = np.cumsum(np.exp(log_probs), axis=-1) < self.rng.random((len(logits), 1))
            chosen = np.minimum(below.sum(axis=-1), logits.shape[-1] - 1)
        picked = np.take_along_axis(log_probs, chosen[:, None], axis=-1)[:, 0]
        return chosen[:, None].astype(np.float32), picked.astype(np.float32)

    def value(self, observations: np.ndarray, critic_tasks: np.ndarray | None = None) -> np.ndarray:
        """Values (n,) of raw observations, with each episode's task where the critic reads it (``act``)."""
        if self.spec.critic_task_dim and critic_tasks is None:
            raise ValueError("this policy's critic reads the task: pass each observation's critic_tasks")
        return self._forward(observations, critic_tasks)[1]


def _dense_only(head: tuple[Layer, ...]) -> TypeGuard[tuple[DenseLayer, ...]]:
    return all(isinstance(layer, DenseLayer) for layer in head)


def _fuse(actor: tuple[DenseLayer, ...], critic: tuple[DenseLayer, ...]) -> tuple[DenseLayer, ...] | None:
    """One stack computing both heads side by side (actor outputs first), or None where their inputs
    differ in width (a critic that reads the task) or their layers in number or activations. Both heads
    read the same input, so the first layers stack their rows; later ones are block-diagonal, each half
    reading its own head's features."""
    if len(actor) != len(critic) or any(a.activations != c.activations for a, c in zip(actor, critic, strict=True)):
        return None
    if actor[0].weight.shape[1] != critic[0].weight.shape[1]:
        return None
    first = DenseLayer(
        np.concatenate([actor[0].weight, critic[0].weight]),
        np.concatenate([actor[0].bias, critic[0].bias]),
        actor[0].activations,
    )
    later = (
        DenseLayer(_block_diagonal(a.weight, c.weight), np.concatenate([a.bias, c.bias]), a.activations)
        for a, c in zip(actor[1:], critic[1:], strict=True)
    )
    return (first, *later)


def _prepared(head: tuple[Layer, ...]) -> _Head:
    image_steps: list[Activation] = []
    stages: list[_Stage] = []
    for layer in head:
        if isinstance(layer, DenseLayer):
            stages.append(_stage(layer))
        elif stages:
            raise ValueError(f"{type(layer).__name__} after a DenseLayer: a head's image layers come first")
        elif isinstance(layer, ConvLayer):
            image_steps.append(_Convolution(layer))
        else:
            image_steps.append(partial(_images, shape=layer.shape))
    return image_steps, stages


def _images(observations: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    images: np.ndarray = (observations * np.float32(PIXEL_SCALE)).reshape(-1, *shape)
    return images


class _Convolution:
    """A ``ConvLayer`` ready to run on channels-last images: every patch (one strided view, no copy until the
    reshape), times the filters as one (in_channels * kernel_height * kernel_width, out_channels) matrix."""

    def __init__(self, layer: ConvLayer) -> None:
        out_channels, _, kernel_height, kernel_width = layer.weight.shape
        # A patch's view is laid out (in_channels, kernel_height, kernel_width), as each filter is stored.
        self.weight = np.ascontiguousarray(layer.weight.reshape(out_channels, -1).T, dtype=np.float32)
        self.bias = layer.bias.astype(np.float32)
        self.kernel = (kernel_height, kernel_width)
        self.stride = layer.stride
        self.activations = layer.activations

    def __call__(self, images: np.ndarray) -> np.ndarray:
        row_step, column_step = self.stride
        patches = sliding_window_view(images, self.kernel, axis=(1, 2))[:, ::row_step, ::column_step]
        count, height, width = patches.shape[:3]
        hidden = (patches.reshape(count * height * width, -1) @ self.weight + self.bias).reshape(
            count, height, width, -1
        )
        for activation in self.activations:
            hidden = activation(hidden)
        return hidden


def _stage(layer: DenseLayer) -> _Stage:
    return np.ascontiguousarray(layer.weight.T, dtype=np.float32), layer.bias.astype(np.float32), layer.activations


def _run(head: _Head, hidden: np.ndarray) -> np.ndarray:
    image_steps, stages = head
    for step in image_steps:
        hidden = step(hidden)
    for weight, bias, activations in stages:
        hidden = hidden @ weight + bias
        for activation in activations:
            hidden = activation(hidden)
    return hidden


def _block_diagonal(upper: np.ndarray, lower: np.ndarray) -> np.ndarray:
    joined = np.zeros((upper.shape[0] + lower.shape[0], upper.shape[1] + lower.shape[1]), dtype=upper.dtype)
    joined[: upper.shape[0], : upper.shape[1]] = upper
    joined[upper.shape[0] :, upper.shape[1] :] = lower
    return joined
