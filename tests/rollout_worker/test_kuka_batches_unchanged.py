"""The sampler's KUKA batches are those it made before it learned discrete actions, scores and score-only
episodes (issue 58): every array of two batches from KUKA environments, with a fixed policy and fixed tasks,
matches the arrays recorded then, with episodes scored or not (scoring only reads the batches).

Equal to float32 rounding, not bit for bit: numpy's OpenBLAS and torch pick their kernels by the CPU's vector
width, and the same commit moves the last bits of observations and actions by up to about 2e-6 between those
paths (measured with ``OPENBLAS_CORETYPE`` and ``ATEN_CPU_CAPABILITY``). Discrete outcomes (tasks, episode
ends, successes, lengths) must match exactly. The recorded file was made on OpenBLAS's Haswell path, where
its arrays hash to the digest recorded at issue 58 before the change; ``PYTHONPATH=. .venv/bin/python
tests/rollout_worker/test_kuka_batches_unchanged.py`` records it again."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from common.client.teacher_client import Assignment
from common.kuka.env import KukaGraspEnv
from common.kuka.task_space import KUKA_TASK_SPACE
from common.policy.actor_critic import ActorCritic, InferencePolicy, PolicySpec, capture_snapshot
from common.policy.normalizer import RunningNormalizer
from rollout_worker.sampler import Sampler, ScoreDiscount

RECORDED = Path(__file__).with_name("kuka_batches_recorded.npz")
FLOAT_ARRAYS = ("observations", "actions", "log_probs", "values", "rewards", "final_values", "last_values")
EXACT_ARRAYS = ("terminated", "truncated")
TOLERANCE = 1e-5
"""Five times the largest difference between kernel paths; a changed seed, step or task moves values by far more."""


class FixedTasks:
    def __init__(self) -> None:
        self.rng = np.random.default_rng(3)
        self.count = 0

    def next_task(self) -> Assignment:
        self.count += 1
        return Assignment(f"task:{self.count}", KUKA_TASK_SPACE.from_array(self.rng.uniform(0.0, 1.0, 6)))

    def report(self, episode: object) -> None:
        pass


def sampled_arrays(score_discount: ScoreDiscount | None) -> dict[str, np.ndarray]:
    """Two batches' arrays and their finished episodes, keyed ``"<batch>/<name>"``."""
    torch.manual_seed(0)
    network = ActorCritic(PolicySpec(obs_dim=9, action_dim=3, hidden_sizes=(16, 16), angle_indices=(3, 4, 5, 8)))
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.3 * torch.randn_like(parameter))
    policy = InferencePolicy(capture_snapshot(network, RunningNormalizer(13), version=1), seed=4)
    envs = [KukaGraspEnv(max_steps=25) for _ in range(2)]
    arrays: dict[str, np.ndarray] = {}
    try:
        sampler = Sampler(envs, FixedTasks(), seed=9, score_discount=score_discount)
        for index in range(2):
            batch = sampler.sample(policy, 20)
            for name in FLOAT_ARRAYS + EXACT_ARRAYS:
                arrays[f"{index}/{name}"] = np.asarray(getattr(batch, name))
            episodes = batch.episodes
            arrays[f"{index}/episode_tasks"] = np.array(
                [[episode.task[name] for name in KUKA_TASK_SPACE.names] for episode in episodes], dtype=np.float64
            ).reshape(len(episodes), len(KUKA_TASK_SPACE.names))
            arrays[f"{index}/episode_rewards"] = np.array([episode.reward for episode in episodes], dtype=np.float64)
            arrays[f"{index}/episode_successes"] = np.array([episode.success for episode in episodes], dtype=bool)
            arrays[f"{index}/episode_lengths"] = np.array([episode.length for episode in episodes], dtype=np.int64)
    finally:
        for env in envs:
            env.close()
    return arrays


@pytest.mark.parametrize("score_discount", [None, ScoreDiscount(0.999, 0.99)], ids=["unscored", "scored"])
def test_kuka_batches_match_the_recorded_ones(score_discount: ScoreDiscount | None) -> None:
    sampled = sampled_arrays(score_discount)
    with np.load(RECORDED) as recorded:
        assert sorted(sampled) == sorted(recorded.files)
        for key, expected in recorded.items():
            assert sampled[key].shape == expected.shape, key
            if key.rsplit("/", 1)[1] in FLOAT_ARRAYS + ("episode_rewards",):
                np.testing.assert_allclose(sampled[key], expected, rtol=TOLERANCE, atol=TOLERANCE, err_msg=key)
            else:
                np.testing.assert_array_equal(sampled[key], expected, err_msg=key)
    # The recording holds finished episodes, so the exact comparisons above are not over empty arrays.
    assert sampled["1/episode_lengths"].size > 0


if __name__ == "__main__":
    np.savez_compressed(RECORDED, **sampled_arrays(None))
