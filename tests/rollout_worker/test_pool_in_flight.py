"""Calls in flight on a pool's slots, made all at once or slot by slot, with real Ray actors."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
import ray

from rollout_worker.pool import InFlight


@ray.remote(num_cpus=0)
class Clock:
    """A stand-in rollout actor: each call sleeps, then says when it started and ended."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds

    def work(self, label: str) -> tuple[str, float, float]:
        started = time.monotonic()
        time.sleep(self.seconds)
        return label, started, time.monotonic()


class Slots:
    """What ``InFlight`` needs of a ``WorkerPool``: one actor per slot (none die here)."""

    def __init__(self, workers: list[Any]) -> None:
        self.workers = workers

    @property
    def size(self) -> int:
        return len(self.workers)

    def worker(self, slot: int) -> Any:
        return self.workers[slot]

    def replace_if_current(self, slot: int, dead: Any) -> None:
        raise AssertionError("no actor dies in these tests")


@pytest.fixture()
def fast_and_slow(ray_cluster: str) -> Iterator[Slots]:
    # The slow call is long enough that a loaded machine (two test processes beside a training run) cannot
    # delay the fast slot's next call past its end by scheduling alone.
    slots = Slots([Clock.remote(0.05), Clock.remote(3.0)])
    yield slots
    for worker in slots.workers:
        ray.kill(worker)


def test_each_slot_starts_its_next_call_as_soon_as_it_has_answered(fast_and_slow: Slots) -> None:
    first = InFlight(fast_and_slow, lambda worker, slot: worker.work.remote(f"first-{slot}"))
    following = InFlight(fast_and_slow, lambda worker, slot: worker.work.remote(f"next-{slot}"), send=False)
    arrivals: list[int] = []

    def start_next(slot: int) -> None:
        arrivals.append(slot)
        following.send(slot)

    current = first.result(on_arrival=start_next)
    assert [label for label, _, _ in current] == ["first-0", "first-1"]
    assert arrivals == [0, 1], "the fast slot answers first"
    nexts = following.result()
    assert [label for label, _, _ in nexts] == ["next-0", "next-1"]
    slow_first_ended = current[1][2]
    fast_next_started = nexts[0][1]
    assert fast_next_started < slow_first_ended, "the fast slot waited for the slow one"


def test_a_call_left_unsent_is_not_done_and_cannot_be_collected(fast_and_slow: Slots) -> None:
    pending = InFlight(fast_and_slow, lambda worker, slot: worker.work.remote(str(slot)), send=False)
    pending.send(0)
    assert not pending.done()
    with pytest.raises(RuntimeError, match=r"slots \[1\] were never sent"):
        pending.result()
    pending.send(1)
    assert [label for label, _, _ in pending.result()] == ["0", "1"]
    assert pending.done()
