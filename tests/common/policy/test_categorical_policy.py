"""A categorical policy (a ``Discrete`` action space, MiniGrid's): the numpy policy the workers act with
draws its choices with the probabilities and log-probabilities of the torch network the learner trains,
whose log-probability and entropy are those of ``torch.distributions.Categorical``."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from common.policy.actor_critic import ActorCritic, InferencePolicy, ObservationFeatures, PolicySpec, capture_snapshot
from common.policy.normalizer import RunningNormalizer

SPEC = PolicySpec(obs_dim=6, action_dim=4, hidden_sizes=(16, 8), categorical=True)


@pytest.fixture()
def network_and_normalizer() -> tuple[ActorCritic, RunningNormalizer]:
    torch.manual_seed(0)
    network = ActorCritic(SPEC)
    with torch.no_grad():  # the logits' layer starts near zero (near-uniform choices), which would hide mistakes
        for parameter in network.parameters():
            parameter.add_(0.5 * torch.randn_like(parameter))
    normalizer = RunningNormalizer(SPEC.feature_dim)
    normalizer.update(np.random.default_rng(0).normal(3.0, 2.0, size=(100, SPEC.obs_dim)))
    return network, normalizer


def inputs(normalizer: RunningNormalizer, observations: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(normalizer.normalize(ObservationFeatures(SPEC)(observations)))


def test_the_network_scores_choices_as_torch_categorical(network_and_normalizer):
    network, normalizer = network_and_normalizer
    observations = inputs(normalizer, np.random.default_rng(1).normal(3.0, 2.0, size=(5, SPEC.obs_dim)))
    actions = torch.tensor([[0.0], [3.0], [1.0], [2.0], [3.0]])
    log_probs, entropy, values = network.evaluate(observations, actions)
    reference = torch.distributions.Categorical(logits=network.actor_mean(observations))
    assert torch.allclose(log_probs, reference.log_prob(actions[:, 0].long()), atol=1e-6)
    assert torch.allclose(entropy, reference.entropy(), atol=1e-6)
    assert torch.allclose(values, network.value(observations))
    assert not hasattr(network, "actor_log_std")
    log_probs.sum().backward()  # gradients reach the logits' layer
    assert network.actor_mean[-1].weight.grad is not None and network.actor_mean[-1].weight.grad.abs().sum() > 0


def test_inference_draws_each_choice_as_often_as_the_network_says(network_and_normalizer):
    network, normalizer = network_and_normalizer
    snapshot = capture_snapshot(network, normalizer, version=4)
    assert snapshot.log_std is None
    policy = InferencePolicy(snapshot, seed=2)
    observation = np.random.default_rng(3).normal(3.0, 2.0, size=(1, SPEC.obs_dim)).astype(np.float32)
    repeated = np.repeat(observation, 20_000, axis=0)

    actions, log_probs, values = policy.act(repeated)

    assert actions.shape == (20_000, 1) and actions.dtype == np.float32
    assert set(np.unique(actions)) <= {0.0, 1.0, 2.0, 3.0}
    probabilities = torch.softmax(network.actor_mean(inputs(normalizer, observation)), -1)[0].detach().numpy()
    frequencies = np.bincount(actions[:, 0].astype(int), minlength=4) / len(actions)
    assert frequencies == pytest.approx(probabilities, abs=0.015)
    assert np.exp(log_probs) == pytest.approx(probabilities[actions[:, 0].astype(int)], abs=1e-5)
    expected_value = network.value(inputs(normalizer, observation)).item()
    assert values == pytest.approx(np.full(20_000, expected_value), abs=1e-5)
    greedy, _, _ = policy.act(observation, deterministic=True)
    assert greedy[0, 0] == float(np.argmax(probabilities))


def test_log_probabilities_match_the_network_on_many_observations(network_and_normalizer):
    network, normalizer = network_and_normalizer
    policy = InferencePolicy(capture_snapshot(network, normalizer, version=0), seed=5)
    observations = np.random.default_rng(4).normal(3.0, 2.0, size=(50, SPEC.obs_dim)).astype(np.float32)
    actions, log_probs, values = policy.act(observations)
    expected_log_probs, _, expected_values = network.evaluate(
        inputs(normalizer, observations), torch.from_numpy(actions)
    )
    assert log_probs == pytest.approx(expected_log_probs.detach().numpy(), abs=1e-5)
    assert values == pytest.approx(expected_values.detach().numpy(), abs=1e-5)


@pytest.mark.parametrize(
    "options", [{"state_dependent_std": True}, {"min_log_std": -2.0}, {"action_dim": 1}], ids=lambda o: next(iter(o))
)
def test_a_categorical_spec_refuses_the_gaussian_options(options):
    with pytest.raises(ValueError, match="categorical"):
        PolicySpec(**{"obs_dim": 3, "action_dim": 3, "categorical": True, **options})
