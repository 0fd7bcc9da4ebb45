"""A critic that reads the task (``PolicySpec.critic_task_dim``), and a critic whose outputs are standardised
values (``capture_snapshot``'s ``value_scale``): the numpy policy the workers run computes the values the torch
network does, and the actor is untouched by either."""

import numpy as np
import pytest
import torch

from common.policy.actor_critic import ActorCritic, InferencePolicy, ObservationFeatures, PolicySpec, capture_snapshot
from common.policy.normalizer import RunningNormalizer

TASK_DIM = 3


def perturbed_network(spec: PolicySpec, seed: int) -> ActorCritic:
    """Weights far from their initialisation (the output layers start near zero, which hides mistakes)."""
    torch.manual_seed(seed)
    network = ActorCritic(spec)
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.3 * torch.randn_like(parameter))
    return network


def fitted_normalizer(spec: PolicySpec) -> RunningNormalizer:
    normalizer = RunningNormalizer(spec.feature_dim)
    normalizer.update(ObservationFeatures(spec)(np.random.default_rng(0).normal(50.0, 4.0, size=(200, spec.obs_dim))))
    return normalizer


def observations_and_tasks(spec: PolicySpec, count: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    observations = rng.normal(50.0, 4.0, size=(count, spec.obs_dim)).astype(np.float32)
    return observations, rng.uniform(0.0, 1.0, size=(count, TASK_DIM)).astype(np.float32)


@pytest.mark.parametrize(
    "options",
    [{}, {"angle_indices": (1, 3)}, {"state_dependent_std": True}],
    ids=["plain", "angles", "state-dependent-std"],
)
def test_the_workers_critic_reads_the_task_as_the_network_does(options):
    """The actor's head reads the features alone and the critic's the features then the task: with the first
    layers of different widths the heads cannot be fused, and each still matches torch."""
    spec = PolicySpec(obs_dim=5, action_dim=2, hidden_sizes=(8, 6), critic_task_dim=TASK_DIM, **options)
    network, normalizer = perturbed_network(spec, seed=0), fitted_normalizer(spec)
    assert network.critic[0].in_features == spec.feature_dim + TASK_DIM == spec.critic_input_dim
    assert network.actor_mean[0].in_features == spec.feature_dim
    policy = InferencePolicy(capture_snapshot(network, normalizer, version=0), seed=3)
    observations, tasks = observations_and_tasks(spec, 9)

    actions, log_probs, values = policy.act(observations, critic_tasks=tasks)

    inputs = torch.from_numpy(normalizer.normalize(ObservationFeatures(spec)(observations)))
    expected_log_probs, _, expected_values = network.evaluate(
        inputs, torch.from_numpy(actions), torch.from_numpy(tasks)
    )
    assert log_probs == pytest.approx(expected_log_probs.detach().numpy(), abs=1e-4)
    assert values == pytest.approx(expected_values.detach().numpy(), abs=1e-5)
    assert policy.value(observations, tasks) == pytest.approx(values, abs=1e-6)
    other_tasks = 1.0 - tasks
    assert not np.allclose(policy.value(observations, other_tasks), values, atol=1e-3)  # the task matters


def test_without_the_task_the_actor_acts_alone_as_in_an_evaluation():
    spec = PolicySpec(obs_dim=5, action_dim=2, hidden_sizes=(8,), critic_task_dim=TASK_DIM)
    network, normalizer = perturbed_network(spec, seed=1), fitted_normalizer(spec)
    snapshot = capture_snapshot(network, normalizer, version=0)
    observations, tasks = observations_and_tasks(spec, 4)

    with_tasks = InferencePolicy(snapshot, seed=2).act(observations, critic_tasks=tasks)
    alone = InferencePolicy(snapshot, seed=2).act(observations)

    assert np.array_equal(with_tasks[0], alone[0]) and np.array_equal(with_tasks[1], alone[1])
    assert np.isnan(alone[2]).all()
    with pytest.raises(ValueError, match="critic reads the task"):
        InferencePolicy(snapshot).value(observations)
    with pytest.raises(ValueError, match="critic reads the task"):
        network.value(torch.zeros(4, spec.feature_dim))


def test_an_image_observation_has_no_critic_that_reads_the_task():
    with pytest.raises(ValueError, match="needs a flat observation"):
        PolicySpec(obs_dim=7 * 7 * 3, action_dim=7, categorical=True, image_shape=(7, 7, 3), critic_task_dim=1)
    with pytest.raises(ValueError, match="critic_task_dim must be 0 or more"):
        PolicySpec(obs_dim=5, action_dim=2, critic_task_dim=-1)


@pytest.mark.parametrize("critic_task_dim", [0, TASK_DIM], ids=["fused-heads", "task-critic"])
def test_a_standardised_critic_gives_the_workers_values_in_return_units(critic_task_dim):
    """The snapshot folds (mean, std) into the critic's last layer: the workers' values are mean + std x the
    network's output, fused with the actor or not, and the actor's outputs are untouched."""
    spec = PolicySpec(obs_dim=5, action_dim=2, hidden_sizes=(8, 6), critic_task_dim=critic_task_dim)
    network, normalizer = perturbed_network(spec, seed=4), fitted_normalizer(spec)
    observations, tasks = observations_and_tasks(spec, 6)
    critic_tasks = tasks if critic_task_dim else None
    plain = InferencePolicy(capture_snapshot(network, normalizer, version=0), seed=5)
    scaled = InferencePolicy(capture_snapshot(network, normalizer, version=0, value_scale=(250.0, 40.0)), seed=5)

    inputs = torch.from_numpy(normalizer.normalize(ObservationFeatures(spec)(observations)))
    outputs = network.value(inputs, None if critic_tasks is None else torch.from_numpy(critic_tasks)).detach().numpy()
    actions, log_probs, values = scaled.act(observations, critic_tasks=critic_tasks)
    assert values == pytest.approx(250.0 + 40.0 * outputs, rel=1e-5, abs=1e-4)
    assert scaled.value(observations, critic_tasks) == pytest.approx(values, rel=1e-6)
    plain_actions, plain_log_probs, _ = plain.act(observations, critic_tasks=critic_tasks)
    assert np.array_equal(actions, plain_actions) and np.array_equal(log_probs, plain_log_probs)
