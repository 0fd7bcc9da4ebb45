"""A checkpoint written before the student's options (lr floor, state-dependent or floored std) existed
loads, and its policy acts exactly as the same checkpoint read with the options at their defaults."""

from __future__ import annotations

import numpy as np
import torch
from tiny_checkpoint import save_untrained_checkpoint

from common.policy.actor_critic import InferencePolicy
from learner.core.checkpoint import load_checkpoint
from learner.core.policy import policy_snapshot


def test_a_checkpoint_from_before_the_student_options_loads_and_acts_the_same(tmp_path):
    path = save_untrained_checkpoint(tmp_path / "run")
    old = torch.load(path, weights_only=True)
    for name in ("lr_final_fraction", "state_dependent_std", "min_log_std"):
        del old["config"]["ppo"][name]
    old_path = tmp_path / "old.pt"
    torch.save(old, old_path)

    checkpoint = load_checkpoint(old_path)
    assert not checkpoint.config.ppo.state_dependent_std and checkpoint.config.ppo.min_log_std is None
    snapshot, current = policy_snapshot(checkpoint), policy_snapshot(load_checkpoint(path))
    assert snapshot.log_std is not None and np.array_equal(snapshot.log_std, current.log_std)
    observations = np.random.default_rng(0).normal(size=(8, snapshot.spec.obs_dim)).astype(np.float32)
    acted = InferencePolicy(snapshot, seed=2).act(observations)
    for ours, theirs in zip(acted, InferencePolicy(current, seed=2).act(observations), strict=True):
        assert np.array_equal(ours, theirs)
