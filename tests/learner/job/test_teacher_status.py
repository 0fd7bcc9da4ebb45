"""The progress bar's teacher status is polled off the training loop: a dead teacher costs it nothing."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterator

import pytest

from common.client.teacher_client import TeacherClient
from common.kuka.task_space import KUKA_TASK_SPACE
from learner.job.teacher_status import TeacherStatus
from teacher_service.process import ServiceProcess, free_port

INTERVAL_S = 0.1
TIMEOUT_S = 1.0
INSTANT_S = 0.01
"""A status read on the loop must cost no more than this; a request to a dead teacher costs TIMEOUT_S."""


@pytest.fixture
def hanging_url() -> Iterator[str]:
    """A port that accepts connections (the kernel's backlog) and never answers."""
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(16)
        yield f"http://127.0.0.1:{listener.getsockname()[1]}"


def _read(
    status: TeacherStatus, within_s: float, until: Callable[[str], bool] | None = None
) -> tuple[list[str], float]:
    """Read the summary as the training loop does, every iteration, for ``within_s`` or until
    ``until`` says so (failing if it never does): every summary read and the slowest read."""
    reads: list[str] = []
    slowest = 0.0
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        started = time.perf_counter()
        reads.append(status.summary)
        slowest = max(slowest, time.perf_counter() - started)
        if until is not None and until(reads[-1]):
            return reads, slowest
        time.sleep(0.005)
    if until is not None:
        pytest.fail(f"the status did not change as expected within {within_s} s; it says {status.summary!r}")
    return reads, slowest


@pytest.mark.parametrize("dead", ["hanging", "refusing"])
def test_a_dead_teacher_never_slows_the_loop(hanging_url, dead):
    url = hanging_url if dead == "hanging" else f"http://127.0.0.1:{free_port()}"
    with TeacherStatus(url, "run", interval_s=INTERVAL_S, timeout_s=TIMEOUT_S) as status:
        reads, slowest = _read(status, 5 * TIMEOUT_S, until=lambda text: "unreachable since" in text)
        down = reads[-1]
        # Keep reading for several request timeouts: several polls fail meanwhile, no read waits on one.
        later, slowest_later = _read(status, 3 * TIMEOUT_S)
    assert max(slowest, slowest_later) < INSTANT_S, f"a status read took {max(slowest, slowest_later):.3f} s"
    assert down.startswith(f"teacher unreachable since {time.strftime('%H')}:")
    assert set(later) == {down}, "the outage's start moved while the teacher stayed down"


def test_the_status_follows_a_teacher_that_goes_down_and_comes_back(tmp_path):
    with ServiceProcess(tmp_path / "teacher.db") as service:
        with TeacherClient(service.url, "run") as client:
            client.register("random", KUKA_TASK_SPACE)
            client.report(client.next_task(), reward=1.0)
        with TeacherStatus(service.url, "run", interval_s=INTERVAL_S, timeout_s=TIMEOUT_S) as status:
            _read(status, 5 * TIMEOUT_S, until=lambda text: text == "random: 1 results")
            service.kill()
            _, slowest = _read(status, 5 * TIMEOUT_S, until=lambda text: "unreachable since" in text)
            service.start()
            back, slowest_back = _read(status, 5 * TIMEOUT_S, until=lambda text: text.startswith("random:"))
    assert max(slowest, slowest_back) < INSTANT_S
    assert back[-1] == "random: 1 results"


def test_the_status_counts_fits_only_for_a_teacher_that_fits(tmp_path):
    with ServiceProcess(tmp_path / "teacher.db") as service:
        with TeacherClient(service.url, "run") as client:
            client.register("alp-gmm", KUKA_TASK_SPACE, {"fit_rate": 2, "min_components": 1, "max_components": 1})
            for reward in (0.0, 1.0, 0.5, 2.0):
                client.report(client.next_task(), reward=reward)
        with TeacherStatus(service.url, "run", interval_s=INTERVAL_S, timeout_s=TIMEOUT_S) as status:
            _read(
                status,
                30 * TIMEOUT_S,
                until=lambda text: text.startswith("alp-gmm: 4 results, ") and "0 fits" not in text,
            )
