"""Press Ctrl-C on a command the way a terminal does, just after its evaluation pool has started."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time

from spawned_processes import spawned_children

START_TIMEOUT_S = 120
STOP_TIMEOUT_S = 60


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
        while len(spawned_children(child.pid)) < workers:
            assert child.poll() is None and time.monotonic() < deadline, "".join(stderr)
            time.sleep(0.05)
        # Past the pool's start, and still long before its workers have imported torch. The parent
        # ignores Ctrl-C while it starts a process, and starting one waits for the child to read its
        # start-up data (the policy's weights among them): on a loaded machine a child took longer
        # than the 0.2 s this waited before, and the Ctrl-C was lost (both full runs of 2026-11-29).
        time.sleep(1.0)
        os.killpg(child.pid, signal.SIGINT)
        code = child.wait(timeout=STOP_TIMEOUT_S)
    finally:
        child.kill()
    reader.join(timeout=10)
    return code, "".join(stderr)
