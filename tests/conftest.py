"""Fixtures shared across packages: one local Ray cluster for the whole test session."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")
"""One OpenMP thread in the test processes and every process they start, before any of them imports torch.
The suite runs a test process per core, so torch's default of a thread per core puts two threads on each
core, and OpenMP's threads spin while they wait for one another: SB3's example took 110 s of CPU with the
default and 19 s with one thread on this machine, beside other work (docs/development.md). torch reads it for its
own threads too, so the PPO tests compute on one thread, as the trainer does."""

pytest_plugins = ["tests.docker_stack"]
"""The Docker stack the Docker tests share: its fixtures, and the Docker tests run last."""

RAY_TEST_CPUS = 4
"""Logical CPUs: two rollout actors plus room for a replacement while a killed one is reaped."""


@pytest.fixture(scope="session")
def ray_cluster() -> Iterator[str]:
    """Start a local Ray once per session; yields its address so subprocesses can join it."""
    import ray

    context = ray.init(
        num_cpus=RAY_TEST_CPUS, include_dashboard=False, log_to_driver=False, namespace="kuka-curriculum-tests"
    )
    try:
        yield context.address_info["address"]
    finally:
        ray.shutdown()
