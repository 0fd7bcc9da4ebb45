import pickle

import numpy as np
import pytest
import torch
from torch import nn

from common.kuka.bullet import pybullet
from common.policy.actor_critic import (
    ActorCritic,
    InferencePolicy,
    ObservationFeatures,
    PolicySnapshot,
    PolicySpec,
    capture_snapshot,
)
from common.policy.inference import WorldOffset
from common.policy.normalizer import RunningNormalizer


@pytest.fixture(params=[(), (1, 3)], ids=["raw", "angles"])
def trained_looking(request):
    """A network with non-trivial weights and a normaliser that has seen offset, scaled data."""
    torch.manual_seed(0)
    spec = PolicySpec(obs_dim=5, action_dim=2, hidden_sizes=(8, 6), init_log_std=-0.3, angle_indices=request.param)
    network = ActorCritic(spec)
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.3 * torch.randn_like(parameter))
    normalizer = RunningNormalizer(spec.feature_dim)
    raw = np.random.default_rng(0).normal(50.0, 4.0, size=(200, 5))
    normalizer.update(ObservationFeatures(spec)(raw))
    return network, normalizer


def test_inference_matches_the_training_network_on_normalised_observations(trained_looking):
    network, normalizer = trained_looking
    policy = InferencePolicy(capture_snapshot(network, normalizer, version=7), seed=3)
    observations = np.random.default_rng(1).normal(50.0, 4.0, size=(6, 5)).astype(np.float32)

    actions, log_probs, values = policy.act(observations)

    inputs = torch.from_numpy(normalizer.normalize(ObservationFeatures(network.spec)(observations)))
    expected_log_probs, _, expected_values = network.evaluate(inputs, torch.from_numpy(actions))
    assert log_probs == pytest.approx(expected_log_probs.detach().numpy(), abs=1e-4)
    assert values == pytest.approx(expected_values.detach().numpy(), abs=1e-5)
    assert policy.value(observations) == pytest.approx(values, abs=1e-6)
    deterministic, _, _ = policy.act(observations, deterministic=True)
    assert deterministic == pytest.approx(network.actor_mean(inputs).detach().numpy(), abs=1e-5)
    assert policy.version == 7


def assert_matches_the_network(network: ActorCritic, normalizer: RunningNormalizer, snapshot: PolicySnapshot) -> None:
    """Sampled actions' log-probabilities, values and deterministic actions as the torch network computes them."""
    spec = network.spec
    policy = InferencePolicy(snapshot, seed=5)
    observations = np.random.default_rng(2).normal(50.0, 4.0, size=(9, spec.obs_dim)).astype(np.float32)

    actions, log_probs, values = policy.act(observations)
    deterministic, _, _ = policy.act(observations, deterministic=True)

    inputs = torch.from_numpy(normalizer.normalize(ObservationFeatures(spec)(observations)))
    expected_log_probs, _, expected_values = network.evaluate(inputs, torch.from_numpy(actions))
    assert actions.shape == (9, spec.action_dim) and values.shape == (9,)
    assert log_probs == pytest.approx(expected_log_probs.detach().numpy(), abs=1e-4)
    assert values == pytest.approx(expected_values.detach().numpy(), abs=1e-4)
    assert deterministic == pytest.approx(network.mean_and_log_std(inputs)[0].detach().numpy(), abs=1e-4)


def perturbed(network: ActorCritic) -> ActorCritic:
    """Weights far from their initialisation (the output layers start near zero, which hides mistakes)."""
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.3 * torch.randn_like(parameter))
    return network


def fitted_normalizer(spec: PolicySpec) -> RunningNormalizer:
    normalizer = RunningNormalizer(spec.feature_dim)
    normalizer.update(ObservationFeatures(spec)(np.random.default_rng(0).normal(50.0, 4.0, size=(200, spec.obs_dim))))
    return normalizer


@pytest.mark.parametrize(
    ("obs_dim", "action_dim", "hidden_sizes", "angle_indices"),
    [(5, 2, (), ()), (5, 2, (8,), (0,)), (9, 3, (32, 16, 8), (1, 4)), (4, 1, (64, 64), ())],
    ids=["linear", "one-hidden", "three-hidden", "kuka-width"],
)
def test_inference_follows_networks_of_every_size(obs_dim, action_dim, hidden_sizes, angle_indices):
    torch.manual_seed(1)
    spec = PolicySpec(obs_dim, action_dim, hidden_sizes, init_log_std=-0.7, angle_indices=angle_indices)
    network, normalizer = perturbed(ActorCritic(spec)), fitted_normalizer(spec)
    assert_matches_the_network(network, normalizer, capture_snapshot(network, normalizer, version=0))


def test_layers_added_to_the_network_are_followed_without_a_change_to_inference():
    """The numpy policy reads the network's layers: a head made deeper, with heads of different depths
    (so they cannot be fused), and with nested containers, still acts as the network does."""
    torch.manual_seed(2)
    spec = PolicySpec(obs_dim=6, action_dim=2, hidden_sizes=(8, 8))
    network = ActorCritic(spec)
    network.actor_mean.append(nn.Tanh())
    network.actor_mean.append(nn.Sequential(nn.Linear(2, 5), nn.Tanh(), nn.Tanh(), nn.Linear(5, 2)))
    network, normalizer = perturbed(network), fitted_normalizer(spec)
    assert_matches_the_network(network, normalizer, capture_snapshot(network, normalizer, version=0))

    network.critic.insert(2, nn.Linear(8, 8))  # the critic deeper too, still not the actor's shape
    network.critic.insert(3, nn.Tanh())
    perturbed(network)
    assert_matches_the_network(network, normalizer, capture_snapshot(network, normalizer, version=1))


def test_heads_with_the_same_depth_but_other_activations_each_keep_their_own():
    torch.manual_seed(3)
    spec = PolicySpec(obs_dim=5, action_dim=2, hidden_sizes=(8, 8))
    network = ActorCritic(spec)
    network.critic.insert(1, nn.Tanh())  # tanh(tanh(x)) after the critic's first layer only
    network, normalizer = perturbed(network), fitted_normalizer(spec)
    assert_matches_the_network(network, normalizer, capture_snapshot(network, normalizer, version=0))


@pytest.mark.parametrize(
    "module", [nn.ELU(), nn.LayerNorm(8), nn.Dropout(0.1)], ids=lambda module: type(module).__name__
)
def test_a_layer_inference_cannot_run_is_refused_when_the_policy_is_captured(module):
    spec = PolicySpec(obs_dim=5, action_dim=2, hidden_sizes=(8,))
    network = ActorCritic(spec)
    network.critic.insert(1, module)
    with pytest.raises(TypeError, match=type(module).__name__):
        capture_snapshot(network, RunningNormalizer(spec.feature_dim), version=0)


def test_a_snapshot_acts_the_same_after_crossing_a_process_boundary(trained_looking):
    """Ray and the evaluation pool pickle snapshots; the layers' activations must survive that."""
    network, normalizer = trained_looking
    snapshot = capture_snapshot(network, normalizer, version=0)
    observations = np.random.default_rng(4).normal(50.0, 4.0, size=(4, 5)).astype(np.float32)

    original = InferencePolicy(snapshot, seed=9).act(observations)
    copied = InferencePolicy(pickle.loads(pickle.dumps(snapshot)), seed=9).act(observations)

    for before, after in zip(original, copied, strict=True):
        assert np.array_equal(before, after)


def test_the_same_seed_draws_the_same_actions_and_new_weights_change_them(trained_looking):
    network, normalizer = trained_looking
    snapshot = capture_snapshot(network, normalizer, version=0)
    observations = np.zeros((3, 5), dtype=np.float32)
    first, again = InferencePolicy(snapshot, seed=11), InferencePolicy(snapshot, seed=11)
    assert np.array_equal(first.act(observations)[0], again.act(observations)[0])

    with torch.no_grad():
        network.actor_mean[0].bias.add_(1.0)
    again.load(capture_snapshot(network, normalizer, version=1))
    assert not np.allclose(
        first.act(observations, deterministic=True)[0], again.act(observations, deterministic=True)[0]
    )
    assert again.version == 1


def test_a_snapshot_of_another_shape_is_refused(trained_looking):
    network, normalizer = trained_looking
    policy = InferencePolicy(capture_snapshot(network, normalizer, version=0))
    other = ActorCritic(
        PolicySpec(obs_dim=5, action_dim=2, hidden_sizes=(4,), angle_indices=network.spec.angle_indices)
    )
    with pytest.raises(ValueError, match="snapshot is for"):
        policy.load(capture_snapshot(other, normalizer, version=1))


def test_an_angle_either_side_of_the_wrap_gives_nearly_the_same_features():
    features = ObservationFeatures(PolicySpec(obs_dim=4, action_dim=1, angle_indices=(1, 3)))
    just_below = np.array([[0.2, np.pi - 1e-3, 7.0, 0.5]])
    just_above = np.array([[0.2, -np.pi + 1e-3, 7.0, 0.5]])

    below, above = features(just_below), features(just_above)

    assert below.shape == (1, 6)
    assert below[0, :2] == pytest.approx([0.2, 7.0])
    assert np.abs(below - above).max() < 3e-3
    assert features(np.array([[0.0, 0.0, 0.0, np.pi / 2]]))[0, 2:] == pytest.approx([0.0, 1.0, 1.0, 0.0], abs=1e-12)


def test_a_world_offset_is_its_vector_turned_by_the_bodys_euler_angles_as_pybullet_turns_it():
    offset = WorldOffset(x_index=0, y_index=1, euler_indices=(2, 3, 4))
    spec = PolicySpec(obs_dim=6, action_dim=1, angle_indices=(2, 3, 4), world_offsets=(offset,))
    features = ObservationFeatures(spec)
    rng = np.random.default_rng(7)
    for _ in range(20):
        vector, euler = rng.uniform(-0.2, 0.2, size=2), rng.uniform(-np.pi, np.pi, size=3)
        rotation = np.array(pybullet.getMatrixFromQuaternion(pybullet.getQuaternionFromEuler(euler))).reshape(3, 3)
        observation = np.array([[*vector, *euler, 3.0]])

        inputs = features(observation)

        assert inputs.shape == (1, 3 + 2 * 3 + 2)  # the 3 plain entries, (sin, cos) of 3 angles, then the offset
        assert inputs[0, -2:] == pytest.approx((rotation @ [*vector, 0.0])[:2], abs=1e-12)


def test_inference_matches_the_training_network_with_a_world_offset():
    torch.manual_seed(8)
    offset = WorldOffset(x_index=4, y_index=5, euler_indices=(0, 1, 2))
    spec = PolicySpec(obs_dim=6, action_dim=2, hidden_sizes=(8, 8), angle_indices=(0, 1, 2), world_offsets=(offset,))
    assert spec.feature_dim == 6 + 3 + 2
    network = perturbed(ActorCritic(spec))
    normalizer = fitted_normalizer(spec)
    assert_matches_the_network(network, normalizer, capture_snapshot(network, normalizer, version=0))


@pytest.mark.parametrize(
    "offset", [WorldOffset(0, 0, (1, 2, 3)), WorldOffset(0, 1, (2, 3, 6)), WorldOffset(-1, 1, (2, 3, 4))]
)
def test_a_world_offset_must_name_distinct_observation_entries(offset):
    with pytest.raises(ValueError, match="world offset"):
        PolicySpec(obs_dim=6, action_dim=1, world_offsets=(offset,))


@pytest.mark.parametrize("angles", [(2, 2), (5,), (-1,)])
def test_angle_indices_must_name_distinct_observation_entries(angles):
    with pytest.raises(ValueError, match="angle_indices"):
        PolicySpec(obs_dim=5, action_dim=1, angle_indices=angles)


def test_a_half_turn_angle_reads_the_same_half_a_turn_on_and_a_plain_angle_does_not():
    features = ObservationFeatures(PolicySpec(obs_dim=4, action_dim=1, angle_indices=(1, 3), half_turn_indices=(3,)))
    pose = np.array([[0.2, 0.4, 7.0, 2.5]])
    half_turned_box = np.array([[0.2, 0.4, 7.0, 2.5 - np.pi]])
    half_turned_gripper = np.array([[0.2, 0.4 - np.pi, 7.0, 2.5]])

    assert features(half_turned_box) == pytest.approx(features(pose), abs=1e-12)
    assert np.abs(features(half_turned_gripper) - features(pose)).max() > 1.0
    # (sin, cos) of the plain angle, then of twice the half-turn one
    assert features(pose)[0, 2:] == pytest.approx([np.sin(0.4), np.sin(5.0), np.cos(0.4), np.cos(5.0)], abs=1e-12)


def test_inference_matches_the_training_network_with_a_half_turn_angle():
    torch.manual_seed(9)
    spec = PolicySpec(obs_dim=5, action_dim=2, hidden_sizes=(8, 8), angle_indices=(0, 4), half_turn_indices=(4,))
    network = perturbed(ActorCritic(spec))
    normalizer = fitted_normalizer(spec)
    assert_matches_the_network(network, normalizer, capture_snapshot(network, normalizer, version=0))


@pytest.mark.parametrize("half_turns", [(2,), (3, 3), (7,)])
def test_half_turn_indices_must_be_distinct_entries_of_angle_indices(half_turns):
    with pytest.raises(ValueError, match="half_turn_indices"):
        PolicySpec(obs_dim=5, action_dim=1, angle_indices=(1, 3), half_turn_indices=half_turns)


def test_a_state_dependent_std_starts_at_its_initial_value_then_varies_with_the_state():
    torch.manual_seed(4)
    spec = PolicySpec(obs_dim=5, action_dim=2, hidden_sizes=(8, 8), init_log_std=-0.7, state_dependent_std=True)
    network = ActorCritic(spec)
    inputs = torch.randn(16, spec.feature_dim)
    _, log_std = network.mean_and_log_std(inputs)
    assert log_std.shape == (16, 2)
    assert log_std.detach().numpy() == pytest.approx(-0.7, abs=0.05)
    assert "actor_log_std" not in dict(network.named_parameters())

    perturbed(network)
    _, log_std = network.mean_and_log_std(inputs)
    assert log_std.std(dim=0).min().item() > 0.05  # each dimension's noise differs from state to state
    log_probs, entropy, _ = network.evaluate(inputs, torch.zeros(16, 2))
    assert entropy.detach().numpy() == pytest.approx((0.5 + 0.5 * np.log(2 * np.pi) + log_std).sum(-1).detach())
    log_probs.sum().backward()
    log_std_rows = network.actor_mean[-1].weight.grad[spec.action_dim :]
    assert log_std_rows.abs().min().item() > 0  # the log-probability's gradient reaches the log-std outputs


@pytest.mark.parametrize("fusable", [True, False], ids=["fused", "separate-heads"])
def test_inference_follows_a_state_dependent_std(fusable):
    torch.manual_seed(5)
    spec = PolicySpec(obs_dim=6, action_dim=3, hidden_sizes=(8, 8), angle_indices=(2,), state_dependent_std=True)
    network = ActorCritic(spec)
    if not fusable:
        network.critic.insert(1, nn.Tanh())
    network, normalizer = perturbed(network), fitted_normalizer(spec)
    snapshot = capture_snapshot(network, normalizer, version=0)
    assert snapshot.log_std is None
    assert_matches_the_network(network, normalizer, snapshot)


@pytest.mark.parametrize(
    ("bias", "min_log_std", "expected"),
    [(10.0, None, 1.0), (-10.0, None, -5.0), (-10.0, -2.0, -2.0)],
    ids=["ceiling", "floor", "min-log-std"],
)
def test_a_state_dependent_log_std_is_clamped_in_training_and_inference_alike(bias, min_log_std, expected):
    torch.manual_seed(6)
    spec = PolicySpec(obs_dim=4, action_dim=2, hidden_sizes=(8,), state_dependent_std=True, min_log_std=min_log_std)
    network = ActorCritic(spec)
    with torch.no_grad():
        network.actor_mean[-1].bias[spec.action_dim :] = bias
    normalizer = fitted_normalizer(spec)
    observations = np.random.default_rng(3).normal(50.0, 4.0, size=(5, 4)).astype(np.float32)
    inputs = torch.from_numpy(normalizer.normalize(observations))
    assert network.mean_and_log_std(inputs)[1].detach().numpy() == pytest.approx(expected)

    policy = InferencePolicy(capture_snapshot(network, normalizer, version=0), seed=1)
    actions, _, _ = policy.act(observations)
    mean, _, _ = policy.act(observations, deterministic=True)
    spread = np.random.default_rng(1).standard_normal(actions.shape, dtype=np.float32) * np.exp(expected)
    assert actions - mean == pytest.approx(spread, rel=1e-4, abs=1e-5)
    assert_matches_the_network(network, normalizer, capture_snapshot(network, normalizer, version=0))


def test_a_log_std_floor_outside_the_clamp_is_refused():
    with pytest.raises(ValueError, match="min_log_std"):
        PolicySpec(obs_dim=4, action_dim=2, min_log_std=-6.0)
