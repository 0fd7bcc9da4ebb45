"""The committed policy in models/ acts bit for bit as it did before the learner learned discrete actions
(issue 58): its sampled actions, their log-probabilities, its values and its deterministic actions on fixed
observations hash to the digest recorded then. A change to the Gaussian path of ``ActorCritic``,
``capture_snapshot`` or ``InferencePolicy`` that moves a single bit fails here.

The observations are numpy's (platform-independent generator), the arithmetic numpy's float32 matmuls; the
digest was recorded on the project's x86-64 machines with the locked numpy."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from common.policy.inference import InferencePolicy
from learner.core.checkpoint import load_checkpoint
from learner.core.kuka_policy import policy_snapshot

MODEL = Path(__file__).parents[2] / "models" / "alp-gmm-3m-seed2.pt"
RECORDED_DIGESTS = {
    "7b63a0e80c20bd017b870f4a4fd055db9f40aaebd6b95bc95fe1cbed8eeec953": "where it was first recorded (issue 58)",
    "ec55f54c301512655e946a9dfa3864144030e8ef026b5affa489f2a44f96bff4": "AMD EPYC, from the landed a828c48 too",
}
"""One digest per floating-point path: float32 matmuls round differently with the CPU's vector width, so a
new kind of machine records its own digest from an unchanged commit; a change that moves a bit fails on all."""


def acted_digest() -> str:
    snapshot = policy_snapshot(load_checkpoint(MODEL))
    policy = InferencePolicy(snapshot, seed=11)
    # Observations of the KUKA's scale (metres and radians), and batches of one, as evaluation acts.
    observations = np.random.default_rng(5).normal(scale=0.5, size=(64, snapshot.spec.obs_dim)).astype(np.float32)
    digest = hashlib.sha256()
    for batch in (observations, observations[:1], observations[7:8]):
        for array in (*policy.act(batch), policy.act(batch, deterministic=True)[0], policy.value(batch)):
            digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def test_the_committed_policy_acts_bit_for_bit_as_recorded() -> None:
    assert acted_digest() in RECORDED_DIGESTS
