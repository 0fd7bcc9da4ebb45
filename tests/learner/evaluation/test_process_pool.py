"""The evaluation pool's workers do not outlive a parent killed with SIGKILL, and its parent answers
Ctrl-C only where the executor holds no lock."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from multiprocessing import get_context
from pathlib import Path

import pytest

from learner.evaluation.process_pool import StoppablePool

PARENT = """
import os, time
from multiprocessing import get_context
from learner.evaluation.process_pool import StoppablePool

def pid_then_wait(_: int) -> int:
    time.sleep(0.2)
    return os.getpid()

if __name__ == "__main__":
    with StoppablePool(2, mp_context=get_context("spawn")) as pool:
        pids = set(pool.map(pid_then_wait, range(8)))
        print(" ".join(map(str, sorted(pids))), flush=True)
        time.sleep(600)  # killed here, its workers idle on their work queue
"""


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    status = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    return status != "Z"


def test_workers_exit_when_their_parent_is_killed(tmp_path: Path) -> None:
    script = tmp_path / "parent.py"  # a file, so spawned workers can import its function
    script.write_text(PARENT)
    environment = {**os.environ, "PYTHONPATH": str(Path.cwd())}
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=environment)
    assert parent.stdout is not None
    workers = [int(pid) for pid in parent.stdout.readline().split()]
    assert workers and all(alive(pid) for pid in workers)
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 10.0
    while any(alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    orphans = [pid for pid in workers if alive(pid)]
    for pid in orphans:
        os.kill(pid, signal.SIGKILL)
    assert not orphans, f"workers {orphans} outlived their killed parent"


@pytest.fixture
def python_ctrl_c() -> Iterator[None]:
    """Python's own Ctrl-C handler, whatever this process inherited: started in the background by a
    shell without job control (``make test &``), Python keeps SIGINT ignored and there is no
    ``KeyboardInterrupt`` to hand on."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.mark.usefixtures("python_ctrl_c")
def test_a_ctrl_c_inside_the_pool_is_held_until_a_safe_point_and_raised_there() -> None:
    reached_the_safe_point = False
    with pytest.raises(KeyboardInterrupt), StoppablePool(2, mp_context=get_context("spawn")) as pool:
        futures = [pool.submit(pow, 2, power) for power in range(8)]
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.3)  # stands for the executor's own code, where a KeyboardInterrupt could strand a lock
        reached_the_safe_point = True
        for _ in pool.as_completed(futures):
            pass
    assert reached_the_safe_point
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_held_ctrl_c_goes_to_the_handler_the_pool_replaced_which_may_let_the_work_go_on() -> None:
    heard: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: heard.append(signum))
    try:
        with StoppablePool(2, mp_context=get_context("spawn")) as pool:
            futures = [pool.submit(pow, 2, power) for power in range(8)]
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.3)
            assert not heard
            results = sorted(pool.result(future) for future in futures)
        assert heard == [signal.SIGINT] and results == [2**power for power in range(8)]
    finally:
        signal.signal(signal.SIGINT, previous)
