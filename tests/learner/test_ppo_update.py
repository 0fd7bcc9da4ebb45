"""PPO's update against values worked out by hand on fixed minibatches.

A PPO with its clip reversed or removed still learns an easy task, so these tests pin the parts one
by one: the clipped surrogate on both sides of the clip for both signs of the advantage (and which
steps still pass a gradient), value clipping, the entropy bonus, the target-KL stop and the
learning-rate schedule. Expected numbers are written out as arithmetic here, never taken from the code.
"""

import math

import numpy as np
import pytest
import torch

from common.policy.actor_critic import PolicySpec
from common.policy.trajectory import TrajectoryBatch
from learner.core.config import PPOConfig
from learner.core.ppo import PPOLearner, ppo_losses

CLIP = 0.2

# Five steps: the ratio above 1 + CLIP and below 1 - CLIP for a positive and for a negative advantage,
# then one inside the clip range.
RATIOS = [1.5, 0.5, 1.5, 0.5, 1.1]
ADVANTAGES = [2.0, 2.0, -1.0, -1.0, 3.0]


def tensor(values: list[float], grad: bool = False) -> torch.Tensor:
    return torch.tensor(values, dtype=torch.float32, requires_grad=grad)


def policy_losses(ratios, advantages, config, old_log_probs=None):
    """The losses of steps whose new/old probability ratios are ``ratios``; the new log-probabilities
    carry gradients. Value and entropy inputs are zeros: these steps test the policy term alone."""
    old = tensor(old_log_probs if old_log_probs is not None else [-0.3 * (i + 1) for i in range(len(ratios))])
    new = (old + tensor([math.log(r) for r in ratios])).detach().requires_grad_(True)
    zeros = tensor([0.0] * len(ratios))
    return new, ppo_losses(new, old, tensor(advantages), zeros, zeros, zeros, zeros, config)


def test_policy_loss_takes_the_pessimistic_surrogate_on_both_sides_of_the_clip():
    config = PPOConfig(clip_coef=CLIP, normalize_advantages=False)
    new_log_probs, losses = policy_losses(RATIOS, ADVANTAGES, config)

    # Per step, min(ratio * A, clip(ratio, 0.8, 1.2) * A):
    objectives = [
        1.2 * 2.0,  # ratio 1.5, A > 0: clipped (3.0 would reward moving further)
        0.5 * 2.0,  # ratio 0.5, A > 0: unclipped 1.0 < 1.6, the mistake is not forgiven
        1.5 * -1.0,  # ratio 1.5, A < 0: unclipped -1.5 < -1.2
        0.8 * -1.0,  # ratio 0.5, A < 0: clipped (-0.5 would reward moving further)
        1.1 * 3.0,  # inside the clip range: both agree
    ]
    assert losses.policy_loss.item() == pytest.approx(-sum(objectives) / 5, rel=1e-5)

    # A clipped step passes no gradient; the others pass -A * ratio / n to their log-probability.
    losses.policy_loss.backward()
    expected_gradient = [0.0, -2.0 * 0.5 / 5, 1.0 * 1.5 / 5, 0.0, -3.0 * 1.1 / 5]
    assert new_log_probs.grad.tolist() == pytest.approx(expected_gradient, rel=1e-5, abs=1e-7)

    # Four of the five ratios lie outside [0.8, 1.2], whichever branch the loss took.
    assert losses.clip_fraction.item() == pytest.approx(4 / 5)
    kl_terms = [(r - 1) - math.log(r) for r in RATIOS]
    assert losses.approx_kl.item() == pytest.approx(sum(kl_terms) / 5, rel=1e-5)


def test_policy_loss_depends_on_the_ratio_only():
    """The same ratios from other log-probabilities give the same losses."""
    config = PPOConfig(clip_coef=CLIP, normalize_advantages=False)
    _, near = policy_losses(RATIOS, ADVANTAGES, config, old_log_probs=[-0.1] * 5)
    _, far = policy_losses(RATIOS, ADVANTAGES, config, old_log_probs=[-7.0, -3.0, -12.0, -0.5, -4.0])
    assert near.policy_loss.item() == pytest.approx(far.policy_loss.item(), rel=1e-5)


def test_advantages_are_standardised_per_minibatch_but_a_single_step_is_left_alone():
    config = PPOConfig(clip_coef=CLIP, normalize_advantages=True)
    _, losses = policy_losses(RATIOS, ADVANTAGES, config)
    mean = (2.0 + 2.0 - 1.0 - 1.0 + 3.0) / 5  # 1.0
    std = math.sqrt(((2.0 - mean) ** 2 * 2 + (-1.0 - mean) ** 2 * 2 + (3.0 - mean) ** 2) / 4)  # sample std
    a = [(advantage - mean) / (std + 1e-8) for advantage in ADVANTAGES]
    # Standardising keeps each advantage's sign here, so the same branches bind as without it.
    assert [x > 0 for x in a] == [x > 0 for x in ADVANTAGES]
    objectives = [1.2 * a[0], 0.5 * a[1], 1.5 * a[2], 0.8 * a[3], 1.1 * a[4]]
    assert losses.policy_loss.item() == pytest.approx(-sum(objectives) / 5, rel=1e-5)

    # The standard deviation of one step is undefined: its advantage is used as it is.
    _, single = policy_losses([1.5], [2.0], config)
    assert single.policy_loss.item() == pytest.approx(-1.2 * 2.0, rel=1e-5)


# Four steps: old value, new value, return.
OLD_VALUES = [1.0, 1.0, 0.0, 0.0]
NEW_VALUES = [1.5, 1.5, -0.1, -1.0]
RETURNS = [2.0, 1.0, 1.0, 0.5]


def value_losses(config):
    new_values = tensor(NEW_VALUES, grad=True)
    zeros = tensor([0.0] * 4)
    losses = ppo_losses(zeros, zeros, zeros, new_values, tensor(OLD_VALUES), tensor(RETURNS), zeros, config)
    losses.value_loss.backward()
    return losses.value_loss.item(), new_values.grad.tolist()


def test_value_loss_with_clipping_takes_the_larger_of_the_clipped_and_unclipped_errors():
    loss, gradient = value_losses(PPOConfig(clip_coef=CLIP, clip_value_loss=True))
    # The new value is held to old +- 0.2: 1.5 -> 1.2, 1.5 -> 1.2, -0.1 stays, -1.0 -> -0.2.
    errors = [
        max((1.5 - 2.0) ** 2, (1.2 - 2.0) ** 2),  # 0.64: the clipped error is larger
        max((1.5 - 1.0) ** 2, (1.2 - 1.0) ** 2),  # 0.25: the unclipped error is larger
        max((-0.1 - 1.0) ** 2, (-0.1 - 1.0) ** 2),  # 1.21: inside the clip range, both agree
        max((-1.0 - 0.5) ** 2, (-0.2 - 0.5) ** 2),  # 2.25: the unclipped error is larger
    ]
    assert errors[0] == (1.2 - 2.0) ** 2 and errors[1] == (1.5 - 1.0) ** 2
    assert loss == pytest.approx(0.5 * sum(errors) / 4, rel=1e-5)
    # d/dv of 0.5 * mean((v - R)^2) is (v - R) / 4 where the unclipped error counts; the clipped error
    # of the first step does not move with v.
    expected = [0.0, (1.5 - 1.0) / 4, (-0.1 - 1.0) / 4, (-1.0 - 0.5) / 4]
    assert gradient == pytest.approx(expected, rel=1e-5, abs=1e-7)


def test_value_loss_without_clipping_is_half_the_mean_squared_error():
    loss, gradient = value_losses(PPOConfig(clip_coef=CLIP, clip_value_loss=False))
    errors = [(1.5 - 2.0) ** 2, (1.5 - 1.0) ** 2, (-0.1 - 1.0) ** 2, (-1.0 - 0.5) ** 2]
    assert loss == pytest.approx(0.5 * sum(errors) / 4, rel=1e-5)
    expected = [(1.5 - 2.0) / 4, (1.5 - 1.0) / 4, (-0.1 - 1.0) / 4, (-1.0 - 0.5) / 4]
    assert gradient == pytest.approx(expected, rel=1e-5)


def test_total_loss_subtracts_the_entropy_bonus_and_weights_the_value_loss():
    config = PPOConfig(
        clip_coef=CLIP, normalize_advantages=False, clip_value_loss=False, entropy_coef=0.01, value_coef=0.5
    )
    entropy = tensor([0.5, 1.5, 2.0, 4.0, 2.0], grad=True)
    old = tensor([-1.0] * 5)
    new = old + tensor([math.log(r) for r in RATIOS])
    new_values = tensor([0.0, 1.0, 2.0, 3.0, 4.0])
    returns = tensor([1.0, 1.0, 1.0, 1.0, 1.0])
    losses = ppo_losses(new, old, tensor(ADVANTAGES), new_values, new_values, returns, entropy, config)

    policy = -(1.2 * 2.0 + 0.5 * 2.0 + 1.5 * -1.0 + 0.8 * -1.0 + 1.1 * 3.0) / 5
    value = 0.5 * ((0.0 - 1.0) ** 2 + 0.0 + (2.0 - 1.0) ** 2 + (3.0 - 1.0) ** 2 + (4.0 - 1.0) ** 2) / 5
    mean_entropy = (0.5 + 1.5 + 2.0 + 4.0 + 2.0) / 5
    assert losses.entropy.item() == pytest.approx(mean_entropy)
    assert losses.value_loss.item() == pytest.approx(value, rel=1e-5)
    assert losses.total.item() == pytest.approx(policy - 0.01 * mean_entropy + 0.5 * value, rel=1e-5)
    # More entropy lowers the loss: the optimiser is paid to keep exploring.
    losses.total.backward()
    assert entropy.grad.tolist() == pytest.approx([-0.01 / 5] * 5, rel=1e-5)


SPEC = PolicySpec(obs_dim=2, action_dim=1, hidden_sizes=(4,))
STEPS, ENVS = 4, 4  # 16 steps: two minibatches of 8 per epoch


def fixed_batch(learner: PPOLearner, log_ratio: float) -> TrajectoryBatch:
    """Sixteen random steps, collected by the learner's current version, whose recorded log-probabilities
    are the learner's own minus ``log_ratio``: every step's ratio starts at exp(log_ratio)."""
    rng = np.random.default_rng(3)
    observations = rng.normal(size=(STEPS, ENVS, SPEC.obs_dim)).astype(np.float32)
    actions = rng.uniform(-1, 1, size=(STEPS, ENVS, SPEC.action_dim)).astype(np.float32)
    normalised = torch.from_numpy(learner.normalizer.normalize(observations.reshape(-1, SPEC.obs_dim)))
    with torch.no_grad():
        log_probs, _, _ = learner.network.evaluate(normalised, torch.from_numpy(actions.reshape(-1, SPEC.action_dim)))
    shape = (STEPS, ENVS)
    return TrajectoryBatch(
        observations=observations,
        actions=actions,
        log_probs=(log_probs.numpy() - log_ratio).reshape(shape),
        values=rng.normal(size=shape).astype(np.float32),
        rewards=rng.normal(size=shape).astype(np.float32),
        terminated=np.zeros(shape, bool),
        truncated=np.zeros(shape, bool),
        final_values=np.zeros(shape, np.float32),
        last_values=np.zeros(ENVS, np.float32),
        policy_version=learner.version,
    )


def optimizer_steps(learner: PPOLearner) -> int:
    """Minibatch updates Adam has taken, from its own per-parameter step counters."""
    counts = {int(state["step"]) for state in learner.optimizer.state.values()}
    assert len(counts) == 1
    return counts.pop()


@pytest.mark.parametrize(
    ("target_kl", "epochs_run"),
    [(None, 5), (1.0, 5), (0.5, 1)],
    ids=["no-target", "kl-under-target", "kl-over-target"],
)
def test_target_kl_ends_the_epoch_loop_after_the_epoch_that_exceeds_it(target_kl, epochs_run):
    """Every step's ratio starts at e, an approximate KL of (e - 1) - 1 = 0.718; a learning rate of
    1e-6 barely moves it. Over 0.5 the loop stops once the first epoch's two minibatches are done."""
    config = PPOConfig(minibatch_size=8, update_epochs=5, learning_rate=1e-6, anneal_lr=False, target_kl=target_kl)
    learner = PPOLearner(SPEC, config, seed=0)
    metrics = learner.update([fixed_batch(learner, log_ratio=1.0)])
    assert optimizer_steps(learner) == epochs_run * (STEPS * ENVS // 8)
    assert metrics["approx_kl"] == pytest.approx((math.e - 1) - 1, rel=1e-3)


@pytest.mark.parametrize(
    ("progress", "share"),
    [(0.0, 1.0), (0.25, 0.75), (0.6, 0.4), (-0.5, 1.0), (1.5, 0.0)],
    ids=["start", "quarter", "past-half", "before-start", "past-the-budget"],
)
def test_learning_rate_falls_linearly_with_the_share_of_the_budget_spent(progress, share):
    lr = 0.01
    config = PPOConfig(minibatch_size=16, update_epochs=1, learning_rate=lr, anneal_lr=True, adam_eps=1e-12)
    learner = PPOLearner(SPEC, config, seed=0)
    before = [parameter.detach().clone() for parameter in learner.network.parameters()]
    metrics = learner.update([fixed_batch(learner, log_ratio=0.1)], progress=progress)

    assert metrics["learning_rate"] == pytest.approx(lr * share)
    assert learner.optimizer.param_groups[0]["lr"] == pytest.approx(lr * share)
    # Adam's first step moves each weight by lr * g / (|g| + eps): the learning rate for any weight with a gradient.
    moved = max(
        (after.detach() - start).abs().max().item()
        for after, start in zip(learner.network.parameters(), before, strict=True)
    )
    assert moved == pytest.approx(lr * share, rel=1e-3, abs=1e-9)


def test_learning_rate_stays_fixed_without_annealing():
    config = PPOConfig(minibatch_size=16, update_epochs=1, learning_rate=0.01, anneal_lr=False)
    learner = PPOLearner(SPEC, config, seed=0)
    for progress in (0.0, 0.5, 0.99):
        metrics = learner.update([fixed_batch(learner, log_ratio=0.1)], progress=progress)
        assert metrics["learning_rate"] == learner.optimizer.param_groups[0]["lr"] == 0.01


@pytest.mark.parametrize(
    ("progress", "share"),
    [(0.0, 1.0), (0.5, 1.0 - 0.5 * 0.75), (1.0, 0.25), (1.5, 0.25)],
    ids=["start", "half", "end-of-budget", "past-the-budget"],
)
def test_learning_rate_anneals_to_its_final_fraction_and_stays_there(progress, share):
    lr = 0.01
    config = PPOConfig(minibatch_size=16, update_epochs=1, learning_rate=lr, lr_final_fraction=0.25, adam_eps=1e-12)
    learner = PPOLearner(SPEC, config, seed=0)
    before = [parameter.detach().clone() for parameter in learner.network.parameters()]
    metrics = learner.update([fixed_batch(learner, log_ratio=0.1)], progress=progress)

    assert metrics["learning_rate"] == pytest.approx(lr * share)
    moved = max(
        (after.detach() - start).abs().max().item()
        for after, start in zip(learner.network.parameters(), before, strict=True)
    )
    assert moved == pytest.approx(lr * share, rel=1e-3, abs=1e-9)


@pytest.mark.parametrize(("floor", "after"), [(None, -3.0), (-2.0, -2.0)], ids=["no-floor", "floor"])
def test_a_shared_log_std_pushed_under_its_floor_is_put_back_on_it(floor, after):
    """An update projects the log-std onto ``min_log_std``; with a learning rate of 1e-9 nothing else moves it."""
    spec = PolicySpec(obs_dim=2, action_dim=1, hidden_sizes=(4,), min_log_std=floor)
    config = PPOConfig(minibatch_size=16, update_epochs=1, learning_rate=1e-9, anneal_lr=False, min_log_std=floor)
    learner = PPOLearner(spec, config, seed=0)
    with torch.no_grad():
        learner.network.actor_log_std.fill_(-3.0)
    metrics = learner.update([fixed_batch(learner, log_ratio=0.1)])

    assert learner.network.actor_log_std.item() == pytest.approx(after, abs=1e-6)
    assert metrics["action_std"] == pytest.approx(math.exp(after), rel=1e-5)


def test_an_update_trains_a_state_dependent_std_through_the_log_std_outputs():
    spec = PolicySpec(obs_dim=2, action_dim=1, hidden_sizes=(4,), state_dependent_std=True)
    config = PPOConfig(minibatch_size=16, update_epochs=2, learning_rate=0.01, state_dependent_std=True)
    learner = PPOLearner(spec, config, seed=0)
    last = learner.network.actor_mean[-1]
    weights, bias = last.weight.detach().clone(), last.bias.detach().clone()
    metrics = learner.update([fixed_batch(learner, log_ratio=0.1)])

    # The second output row is the log-std's: the policy loss reaches it.
    assert not torch.equal(last.weight[1], weights[1]) and not torch.equal(last.bias[1], bias[1])
    assert 0.5 < metrics["action_std"] / math.exp(spec.init_log_std) < 1.5
