"""The sampler's KUKA batches are bit for bit those it made before it learned discrete actions, scores and
score-only episodes (issue 58): every array of two batches from KUKA environments, with a fixed policy and
fixed tasks, hashes to the digest recorded then (on the project's x86-64 machines, with the locked numpy
and pybullet), with episodes scored or not: scoring only reads the batches."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import torch

from common.client.teacher_client import Assignment
from common.kuka.env import KukaGraspEnv
from common.kuka.task_space import KUKA_TASK_SPACE
from common.policy.actor_critic import ActorCritic, InferencePolicy, PolicySpec, capture_snapshot
from common.policy.normalizer import RunningNormalizer
from rollout_worker.sampler import Sampler, ScoreDiscount

RECORDED_DIGESTS = {
    "bde78193b75585edbb555ebf0030164d5ac9a81cd5ee9860242f928518320284": "where it was first recorded (issue 58)",
    "acfd0443e9460b25978c9dae49b0e46ba16662c8ead3085708f41985f286260f": "AMD EPYC, from the landed a828c48 too",
}
"""One digest per floating-point path: float32 matmuls round differently with the CPU's vector width, so a
new kind of machine records its own digest from an unchanged commit; a change that moves a bit fails on all."""
ARRAYS = ("observations", "actions", "log_probs", "values", "rewards", "terminated", "truncated", "final_values")


class FixedTasks:
    def __init__(self) -> None:
        self.rng = np.random.default_rng(3)
        self.count = 0

    def next_task(self) -> Assignment:
        self.count += 1
        return Assignment(f"task:{self.count}", KUKA_TASK_SPACE.from_array(self.rng.uniform(0.0, 1.0, 6)))

    def report(self, episode: object) -> None:
        pass


def sampled_digest(score_discount: ScoreDiscount | None) -> str:
    torch.manual_seed(0)
    network = ActorCritic(PolicySpec(obs_dim=9, action_dim=3, hidden_sizes=(16, 16), angle_indices=(3, 4, 5, 8)))
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.3 * torch.randn_like(parameter))
    policy = InferencePolicy(capture_snapshot(network, RunningNormalizer(13), version=1), seed=4)
    envs = [KukaGraspEnv(max_steps=25) for _ in range(2)]
    try:
        sampler = Sampler(envs, FixedTasks(), seed=9, score_discount=score_discount)
        digest = hashlib.sha256()
        for _ in range(2):
            batch = sampler.sample(policy, 20)
            for name in ARRAYS:
                digest.update(np.ascontiguousarray(getattr(batch, name)).tobytes())
            digest.update(np.ascontiguousarray(batch.last_values).tobytes())
            for episode in batch.episodes:
                digest.update(repr((episode.task, episode.reward, episode.success, episode.length)).encode())
    finally:
        for env in envs:
            env.close()
    return digest.hexdigest()


@pytest.mark.parametrize("score_discount", [None, ScoreDiscount(0.999, 0.99)], ids=["unscored", "scored"])
def test_kuka_batches_are_bit_for_bit_as_recorded(score_discount: ScoreDiscount | None) -> None:
    assert sampled_digest(score_discount) in RECORDED_DIGESTS
