"""A fixed-size set of rollout actors that survives the death of any of them.

A dead actor (crashed, killed, node lost) is replaced by a fresh one with a new seed stream and
asked again for what the dead one owed, so every call returns a full set of results. Calls can be
left in flight (``start_sampling``, ``start_evaluation``) while the learner does other work; an
actor runs its calls in the order they were made. A call can also be made slot by slot
(``start_sampling(..., send=False)`` then ``send``), for instance each slot as soon as it
has delivered its previous batch, so no actor waits for the slowest one.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Generic, TypeVar

import numpy as np
import ray
from ray.exceptions import RayActorError
from ray.util import get_current_placement_group

from common.client.task_space import Task
from common.policy.inference import PolicySnapshot
from common.policy.trajectory import EpisodeStats, TrajectoryBatch
from rollout_worker.actor import RolloutWorker, WorkerSettings

MAX_CONSECUTIVE_DEATHS = 3
"""Replacements for one slot within one call before giving up: an actor that dies on every start is a bug."""

Result = TypeVar("Result")
Submit = Callable[[Any, int], "ray.ObjectRef[Any]"]


class InFlight(Generic[Result]):
    """One call on every slot of a pool, made but not yet collected."""

    def __init__(self, pool: WorkerPool, submit: Submit, send: bool = True) -> None:
        """``send=False``: no slot is called yet; ``send`` each one before ``result``."""
        self._pool = pool
        self._submit = submit
        self._results: list[Any] = [None] * pool.size
        self._deaths = [0] * pool.size
        self._unsent = set() if send else set(range(pool.size))
        self._pending: dict[ray.ObjectRef[Any], tuple[int, Any]] = {}
        if send:
            for slot in range(pool.size):
                self._send(slot)

    def send(self, slot: int) -> None:
        """Make the call on one slot that was left unsent."""
        self._unsent.remove(slot)
        self._send(slot)

    def _send(self, slot: int) -> None:
        worker = self._pool.worker(slot)
        self._pending[self._submit(worker, slot)] = (slot, worker)

    def done(self) -> bool:
        """Whether every slot has answered (a dead actor's answer is its death), without waiting."""
        ready, _ = ray.wait(list(self._pending), num_returns=len(self._pending), timeout=0)
        return not self._unsent and len(ready) == len(self._pending)

    def result(self, on_arrival: Callable[[int], None] | None = None) -> list[Result]:
        """Every slot's result, in slot order; waits, and retries a slot on a fresh actor when its actor dies.

        ``on_arrival(slot)`` runs as each slot's result comes in, while the others are still awaited.
        """
        if self._unsent:
            raise RuntimeError(f"slots {sorted(self._unsent)} were never sent")
        while self._pending:
            [ready], _ = ray.wait(list(self._pending), num_returns=1)
            slot, worker = self._pending.pop(ready)
            try:
                self._results[slot] = ray.get(ready)
            except RayActorError as error:
                self._deaths[slot] += 1
                if self._deaths[slot] > MAX_CONSECUTIVE_DEATHS:
                    raise RuntimeError(
                        f"rollout worker {slot} died {self._deaths[slot]} times in a row; last error: {error}"
                    ) from error
                self._pool.replace_if_current(slot, worker)
                self._send(slot)
                continue
            if on_arrival is not None:
                on_arrival(slot)
        return self._results


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

    @property
    def size(self) -> int:
        return len(self._workers)

    def worker(self, slot: int) -> Any:
        return self._workers[slot]

    def _start(self, slot: int) -> Any:
        """Each slot and incarnation gets its own seed stream, so a replacement never replays its predecessor."""
        incarnation = self._incarnations[slot]
        worker_seed = int(np.random.SeedSequence([self.seed, slot, incarnation]).generate_state(1)[0])
        # Spread over the nodes: each actor is CPU-bound, and a worker machine lost takes fewer of them with it.
        # Inside a placement group that captures its children (a `tune` trial's), take its bundles instead:
        # an explicit strategy would place the actors outside the CPUs the trial claimed.
        in_group = get_current_placement_group() is not None
        options: dict[str, Any] = {} if in_group else {"scheduling_strategy": "SPREAD"}
        if self.name_prefix is not None:
            options["name"] = f"{self.name_prefix}-worker-{slot}-{incarnation}"
        return RolloutWorker.options(**options).remote(self.settings, worker_seed)  # type: ignore[attr-defined]  # ray types @ray.remote(...) as keeping the plain class

    def replace_if_current(self, slot: int, dead: Any) -> None:
        """Replace the slot's actor, unless another call in flight already replaced this dead one."""
        if self._workers[slot] is not dead:
            return
        ray.kill(dead, no_restart=True)
        self._incarnations[slot] += 1
        self.replacements += 1
        self._workers[slot] = self._start(slot)

    def start_sampling(
        self, snapshot: ray.ObjectRef[PolicySnapshot] | PolicySnapshot, send: bool = True
    ) -> InFlight[TrajectoryBatch]:
        """One batch from every worker; pass a ``ray.put`` reference so the weights are shipped once.
        ``send=False`` leaves each slot to be started with ``InFlight.send``."""
        return InFlight(self, lambda worker, _: worker.sample.remote(snapshot), send)

    def sample(self, snapshot: ray.ObjectRef[PolicySnapshot] | PolicySnapshot) -> list[TrajectoryBatch]:
        return self.start_sampling(snapshot).result()

    def start_evaluation(
        self, snapshot: ray.ObjectRef[PolicySnapshot] | PolicySnapshot, task: Task, seeds: Sequence[int]
    ) -> InFlight[list[EpisodeStats]]:
        """One deterministic episode per seed, the seeds shared out over the workers."""
        shares = [list(seeds[slot :: self.size]) for slot in range(self.size)]
        return InFlight(self, lambda worker, slot: worker.evaluate.remote(snapshot, task, shares[slot]))

    def evaluate(
        self, snapshot: ray.ObjectRef[PolicySnapshot] | PolicySnapshot, task: Task, seeds: Sequence[int]
    ) -> list[EpisodeStats]:
        return [episode for share in self.start_evaluation(snapshot, task, seeds).result() for episode in share]

    def close(self, timeout_s: float = 30.0) -> None:
        """Let every worker deliver its buffered episode results, then stop it."""
        closing = [worker.close.remote() for worker in self._workers]
        ray.wait(closing, num_returns=len(closing), timeout=timeout_s)
        for worker in self._workers:
            ray.kill(worker, no_restart=True)
        self._workers = []
