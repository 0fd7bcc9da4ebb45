"""A Ray rollout worker whose teacher goes away keeps sampling, and its batches say what its client
holds and drops, so the learner's log shows an outage."""

from __future__ import annotations

from pathlib import Path

import httpx
import ray
import torch

from common.client.schemas import API_PREFIX
from common.policy.actor_critic import ActorCritic, PolicySpec, capture_snapshot
from common.policy.normalizer import RunningNormalizer
from rollout_worker.actor import RolloutWorker, WorkerSettings
from teacher_service.process import ServiceProcess

ENV_ID = "MiniGrid-DoorKey-5x5-v0"
LEVELS = [{"name": "level", "type": "integer", "low": 0, "high": 99}]


def test_batches_count_the_results_waiting_and_dropped_through_an_outage(ray_cluster: str, tmp_path: Path) -> None:
    torch.manual_seed(0)
    network = ActorCritic(PolicySpec(obs_dim=147, action_dim=7, hidden_sizes=(16,), categorical=True))
    snapshot = ray.put(capture_snapshot(network, RunningNormalizer(147), version=1))
    with ServiceProcess(tmp_path / "teacher.db") as service:
        body = {"teacher": "random", "space": LEVELS}
        assert httpx.put(f"{service.url}{API_PREFIX}/curricula/outage", json=body).status_code == 201
        settings = WorkerSettings(
            service.url, "outage", 4, rollout_length=64, max_episode_steps=20, env_id=ENV_ID, results_buffer=3
        )
        worker = RolloutWorker.remote(settings, 0)  # type: ignore[attr-defined]
        before = ray.get(worker.sample.remote(snapshot))
        assert before.episodes and all(episode.task_id is not None for episode in before.episodes)
        service.kill()
        during = [ray.get(worker.sample.remote(snapshot)) for _ in range(3)]
    ray.kill(worker)
    # 12 results a batch against a buffer of 3 that the dead teacher never empties
    assert sum(batch.results_dropped for batch in [before, *during]) > 0, "the oldest results went, counted"
    assert all(0 < batch.results_waiting <= 3 for batch in during), "held for delivery, never above the cap"
    assert any(episode.task_id is None for batch in during for episode in batch.episodes), "offline episodes"
