"""An image observation (``PolicySpec.image_shape``): each head starts with a small CNN, which the numpy policy
the workers act with runs as the torch network the learner trains does, without the observation normaliser."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch
from torch import nn

from common.policy.actor_critic import (
    ActorCritic,
    ImageInput,
    InferencePolicy,
    PolicySpec,
    capture_snapshot,
    head_layers,
    image_encoder,
)
from common.policy.inference import ConvLayer, WorldOffset
from common.policy.normalizer import RunningNormalizer

HEADS = {
    "gaussian": {"action_dim": 2},
    "state-dependent-std": {"action_dim": 2, "state_dependent_std": True},
    "categorical": {"action_dim": 4, "categorical": True},
}


def image_spec(shape: tuple[int, int, int], **options: object) -> PolicySpec:
    return PolicySpec(obs_dim=int(np.prod(shape)), hidden_sizes=(16, 8), image_shape=shape, **options)


def images(spec: PolicySpec, count: int, seed: int) -> np.ndarray:
    """Flat float32 images of pixels 0..255, as an environment's flattened observations arrive."""
    return np.random.default_rng(seed).integers(0, 256, size=(count, spec.obs_dim)).astype(np.float32)


def perturbed(network: ActorCritic) -> ActorCritic:
    """Weights far from their initialisation (the output layers start near zero, which hides mistakes)."""
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.1 * torch.randn_like(parameter))
    return network


def test_the_network_reads_a_flat_observation_as_height_width_channels_scaled_to_one():
    image = np.zeros((5, 6, 3), dtype=np.float32)
    image[1, 4, 2] = 255.0
    image[3, 0, 0] = 51.0
    batch = ImageInput((5, 6, 3))(torch.from_numpy(image.reshape(1, -1)))
    assert batch.shape == (1, 3, 5, 6)  # (n, channels, height, width), as nn.Conv2d reads it
    assert torch.count_nonzero(batch) == 2
    assert batch[0, 2, 1, 4].item() == pytest.approx(1.0) and batch[0, 0, 3, 0].item() == pytest.approx(0.2)


@pytest.mark.parametrize(
    ("shape", "width"),
    [((7, 7, 3), 3 * 3 * 32), ((5, 5, 1), 1 * 1 * 32), ((20, 16, 1), 7 * 5 * 32), ((64, 64, 3), 15 * 15 * 32)],
    ids=["minigrid-view", "smallest", "strided-once", "64x64"],
)
def test_the_encoder_halves_large_images_only_and_states_its_output_width(shape, width):
    modules, stated = image_encoder(shape)
    encoded = nn.Sequential(*modules)(torch.zeros(2, int(np.prod(shape))))
    assert stated == width and encoded.shape == (2, width)


@pytest.mark.parametrize("shape", [(7, 7, 3), (20, 16, 1), (64, 64, 3)], ids=["7x7x3", "20x16x1", "64x64x3"])
@pytest.mark.parametrize("head", HEADS, ids=str)
def test_inference_matches_the_network_on_images_without_the_normaliser(shape, head):
    torch.manual_seed(0)
    spec = image_spec(shape, **HEADS[head])
    assert not spec.normalizes_observations
    network = perturbed(ActorCritic(spec))
    normalizer = RunningNormalizer(spec.feature_dim)  # statistics far from the pixels': used, they would show
    normalizer.update(np.random.default_rng(0).normal(1000.0, 0.1, size=(4, spec.obs_dim)))
    snapshot = capture_snapshot(network, normalizer, version=3)
    policy = InferencePolicy(snapshot, seed=1)
    observations = images(spec, 9, seed=2)

    actions, log_probs, values = policy.act(observations)
    deterministic, _, _ = policy.act(observations, deterministic=True)

    inputs = torch.from_numpy(observations)  # raw pixels: the network scales them itself
    expected_log_probs, _, expected_values = network.evaluate(inputs, torch.from_numpy(actions))
    assert values.shape == (9,) and actions.shape == (9, 1 if spec.categorical else spec.action_dim)
    assert log_probs == pytest.approx(expected_log_probs.detach().numpy(), abs=1e-4)
    assert values == pytest.approx(expected_values.detach().numpy(), abs=1e-4)
    assert policy.value(observations) == pytest.approx(values, abs=1e-6)
    if spec.categorical:
        assert deterministic[:, 0] == pytest.approx(network.actor_mean(inputs).argmax(-1).numpy())
    else:
        assert deterministic == pytest.approx(network.mean_and_log_std(inputs)[0].detach().numpy(), abs=1e-4)
    assert isinstance(snapshot.actor[1], ConvLayer) and isinstance(snapshot.critic[1], ConvLayer)


def test_an_image_snapshot_acts_the_same_after_crossing_a_process_boundary():
    """Ray pickles snapshots: the encoders' ReLU and flatten must survive it."""
    spec = image_spec((8, 8, 2), action_dim=3, categorical=True)
    snapshot = capture_snapshot(perturbed(ActorCritic(spec)), RunningNormalizer(spec.feature_dim), version=0)
    observations = images(spec, 4, seed=3)

    original = InferencePolicy(snapshot, seed=9).act(observations)
    copied = InferencePolicy(pickle.loads(pickle.dumps(snapshot)), seed=9).act(observations)

    for before, after in zip(original, copied, strict=True):
        assert np.array_equal(before, after)


@pytest.mark.parametrize(
    "options",
    [
        {"obs_dim": 48, "image_shape": (7, 7, 1)},
        {"obs_dim": 16, "image_shape": (4, 4, 1)},
        {"obs_dim": 0, "image_shape": (7, 7, 0)},
        {"obs_dim": 49, "image_shape": (7, 7, 1), "angle_indices": (3,)},
        {"obs_dim": 49, "image_shape": (7, 7, 1), "angle_indices": (3,), "half_turn_indices": (3,)},
        {"obs_dim": 49, "image_shape": (7, 7, 1), "world_offsets": (WorldOffset(0, 1, (2, 3, 4)),)},
    ],
    ids=["obs-dim-not-the-image", "too-small", "no-channels", "angles", "half-turns", "world-offset"],
)
def test_a_spec_that_cannot_describe_an_image_observation_is_refused(options):
    with pytest.raises(ValueError, match="image"):
        PolicySpec(action_dim=2, **options)


@pytest.mark.parametrize(
    "head",
    [
        nn.Sequential(ImageInput((7, 7, 1)), nn.Conv2d(1, 4, 3, padding=1), nn.ReLU(), nn.Flatten(), nn.Linear(196, 2)),
        nn.Sequential(ImageInput((7, 7, 1)), nn.Conv2d(1, 4, 3, dilation=2), nn.Flatten(), nn.Linear(36, 2)),
        nn.Sequential(ImageInput((7, 7, 1)), nn.Conv2d(1, 4, 3), nn.ReLU(), nn.Linear(5, 2)),
        nn.Sequential(ImageInput((7, 7, 1)), nn.Conv2d(1, 4, 3), nn.Flatten(start_dim=2), nn.Linear(25, 2)),
        nn.Sequential(nn.Linear(49, 8), nn.Tanh(), nn.Conv2d(1, 4, 3)),
        nn.Sequential(nn.Linear(49, 8), ImageInput((7, 7, 1))),
        nn.Sequential(ImageInput((7, 7, 1)), nn.ReLU(), nn.Conv2d(1, 4, 3)),
    ],
    ids=["padding", "dilation", "no-flatten", "partial-flatten", "conv-on-features", "image-later", "relu-on-input"],
)
def test_an_image_head_inference_cannot_run_is_refused_when_read(head):
    with pytest.raises(TypeError, match="InferencePolicy cannot run"):
        head_layers(head)
