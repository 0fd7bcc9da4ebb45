"""The committed policy in models/ acts as it did before the learner learned discrete actions (issue 58): its
sampled actions, their log-probabilities, its values and its deterministic actions on fixed observations
match the arrays recorded then. A change to the Gaussian path of ``ActorCritic``, ``capture_snapshot`` or
``InferencePolicy`` fails here.

The observations are numpy's (platform-independent generator), the arithmetic numpy's float32 matmuls, whose
OpenBLAS kernel is picked by the CPU: equal to float32 rounding, not bit for bit. The recorded file was made
on OpenBLAS's Haswell path, where its arrays hash to the digest recorded at issue 58 before the change;
``PYTHONPATH=. .venv/bin/python tests/learner/test_committed_policy_unchanged.py`` records it again."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from common.policy.inference import InferencePolicy
from learner.core.checkpoint import load_checkpoint
from learner.core.policy import policy_snapshot

MODEL = Path(__file__).parents[2] / "models" / "alp-gmm-3m-seed2.pt"
RECORDED = Path(__file__).with_name("committed_policy_recorded.npz")
TOLERANCE = 1e-5
"""Far above float32 rounding between kernel paths, far below what a changed weight, seed or formula moves."""


def acted_arrays() -> dict[str, np.ndarray]:
    """What the policy returns for three batches, keyed ``"<batch>/<output>"``."""
    snapshot = policy_snapshot(load_checkpoint(MODEL))
    policy = InferencePolicy(snapshot, seed=11)
    # Observations of the KUKA's scale (metres and radians), and batches of one, as evaluation acts.
    observations = np.random.default_rng(5).normal(scale=0.5, size=(64, snapshot.spec.obs_dim)).astype(np.float32)
    arrays: dict[str, np.ndarray] = {}
    for index, batch in enumerate((observations, observations[:1], observations[7:8])):
        actions, log_probs, values_while_acting = policy.act(batch)
        arrays[f"{index}/actions"] = actions
        arrays[f"{index}/log_probs"] = log_probs
        arrays[f"{index}/values_while_acting"] = values_while_acting
        arrays[f"{index}/deterministic_actions"] = policy.act(batch, deterministic=True)[0]
        arrays[f"{index}/values"] = policy.value(batch)
    return arrays


def test_the_committed_policy_acts_as_recorded() -> None:
    acted = acted_arrays()
    with np.load(RECORDED) as recorded:
        assert sorted(acted) == sorted(recorded.files)
        for key, expected in recorded.items():
            assert acted[key].dtype == expected.dtype and acted[key].shape == expected.shape, key
            np.testing.assert_allclose(acted[key], expected, rtol=TOLERANCE, atol=TOLERANCE, err_msg=key)


if __name__ == "__main__":
    np.savez_compressed(RECORDED, **acted_arrays())
