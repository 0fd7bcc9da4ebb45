"""A fixed-size set of rollout actors that survives the death of any of them.

A dead actor (crashed, killed, node lost) is replaced by a fresh one with a new seed stream and
asked again for what the dead one owed, so every call returns a full set of results.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import ray
from ray.exceptions import RayActorError

from common.policy import PolicySnapshot
from common.task_space import Task
from common.trajectory import EpisodeStats, TrajectoryBatch
from rollout_worker.actor import RolloutWorker, WorkerSettings

MAX_CONSECUTIVE_DEATHS = 3
"""Replacements for one slot within one call before giving up: an actor that dies on every start is a bug."""


class WorkerPool:
    """``count`` rollout actors addressed by slot; ``name_prefix`` names them for ``ray.get_actor``."""

    def __init__(self, settings: WorkerSettings, count: int, seed: int, name_prefix: str | None = None) -> None:
        if count < 1:
            raise ValueError(f"a worker pool needs at least one worker, got {count}")
        self.settings = settings
        self.seed = seed
        self.name_prefix = name_prefix
        self.replacements = 0
        self._incarnations = [0] * count
        self._workers = [self._start(slot) for slot in range(count)]

    def _start(self, slot: int) -> Any:
        """Each slot and incarnation gets its own seed stream, so a replacement never replays its predecessor."""
        incarnation = self._incarnations[slot]
        worker_seed = int(np.random.SeedSequence([self.seed, slot, incarnation]).generate_state(1)[0])
        # Spread over the nodes: each actor is CPU-bound, and a worker machine lost takes fewer of them with it.
        options: dict[str, Any] = {"scheduling_strategy": "SPREAD"}
        if self.name_prefix is not None:
            options["name"] = f"{self.name_prefix}-worker-{slot}-{incarnation}"
        return RolloutWorker.options(**options).remote(self.settings, worker_seed)  # type: ignore[attr-defined]  # ray types @ray.remote(...) as keeping the plain class

    def _replace(self, slot: int) -> None:
        ray.kill(self._workers[slot], no_restart=True)
        self._incarnations[slot] += 1
        self.replacements += 1
        self._workers[slot] = self._start(slot)

    def _call_all(self, submit: Callable[[Any, int], ray.ObjectRef[Any]]) -> list[Any]:
        """Run ``submit(worker, slot)`` on every slot, retrying a slot on a fresh actor when its actor dies."""
        results: list[Any] = [None] * len(self._workers)
        deaths = [0] * len(self._workers)
        pending = {submit(worker, slot): slot for slot, worker in enumerate(self._workers)}
        while pending:
            [ready], _ = ray.wait(list(pending), num_returns=1)
            slot = pending.pop(ready)
            try:
                results[slot] = ray.get(ready)
            except RayActorError as error:
                deaths[slot] += 1
                if deaths[slot] > MAX_CONSECUTIVE_DEATHS:
                    raise RuntimeError(
                        f"rollout worker {slot} died {deaths[slot]} times in a row; last error: {error}"
                    ) from error
                self._replace(slot)
                pending[submit(self._workers[slot], slot)] = slot
        return results

    def sample(self, snapshot: ray.ObjectRef[PolicySnapshot] | PolicySnapshot) -> list[TrajectoryBatch]:
        """One batch from every worker; pass a ``ray.put`` reference so the weights are shipped once."""
        return self._call_all(lambda worker, _: worker.sample.remote(snapshot))

    def evaluate(
        self, snapshot: ray.ObjectRef[PolicySnapshot] | PolicySnapshot, task: Task, seeds: Sequence[int]
    ) -> list[EpisodeStats]:
        """Play one deterministic episode per seed, the seeds shared out over the workers."""
        shares = [list(seeds[slot :: len(self._workers)]) for slot in range(len(self._workers))]
        results = self._call_all(lambda worker, slot: worker.evaluate.remote(snapshot, task, shares[slot]))
        return [episode for share in results for episode in share]

    def close(self, timeout_s: float = 30.0) -> None:
        """Let every worker deliver its buffered episode results, then stop it."""
        closing = [worker.close.remote() for worker in self._workers]
        ray.wait(closing, num_returns=len(closing), timeout=timeout_s)
        for worker in self._workers:
            ray.kill(worker, no_restart=True)
        self._workers = []
