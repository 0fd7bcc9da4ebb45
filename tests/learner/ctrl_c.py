"""Press Ctrl-C on a command the way a terminal does, just after its evaluation pool has started."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from pathlib import Path

START_TIMEOUT_S = 120
STOP_TIMEOUT_S = 60


def pool_workers(parent: int) -> list[int]:
    """The pids of ``parent``'s spawned multiprocessing children, read from /proc."""
    workers = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rpartition(")")[2].split()
            command = (stat.parent / "cmdline").read_bytes()
        except OSError:
            continue  # it ended while we looked
        if int(fields[1]) == parent and b"spawn_main" in command:
            workers.append(int(stat.parent.name))
    return workers


def ctrl_c_as_the_pool_starts(command: list[str], workers: int) -> tuple[int, str]:
    """Run ``command``; once it has spawned ``workers`` processes, and while they are still importing,
    send SIGINT to its whole process group. Returns its exit code and everything it wrote to stderr."""
    child = subprocess.Popen(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    assert child.stderr is not None
    stderr: list[str] = []
    reader = threading.Thread(target=lambda: stderr.extend(iter(lambda: child.stderr.read(1), "")), daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while len(pool_workers(child.pid)) < workers:
            assert child.poll() is None and time.monotonic() < deadline, "".join(stderr)
            time.sleep(0.05)
        time.sleep(0.2)  # past the pool's start, and still long before its workers have imported torch
        os.killpg(child.pid, signal.SIGINT)
        code = child.wait(timeout=STOP_TIMEOUT_S)
    finally:
        child.kill()
    reader.join(timeout=10)
    return code, "".join(stderr)
