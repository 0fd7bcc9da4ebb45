"""Press Ctrl-C on a command the way a terminal does, just after its evaluation pool has started."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from pathlib import Path

from spawned_processes import spawned_children

START_TIMEOUT_S = 120
STOP_TIMEOUT_S = 60


def ignores_ctrl_c(pid: int) -> bool:
    """Whether the process ignores SIGINT now (its ``SigIgn`` mask in /proc): the pool's parent does
    while it starts a worker, so that the worker is born ignoring it, and a Ctrl-C then is lost."""
    for line in Path(f"/proc/{pid}/status").read_text(encoding="ascii").splitlines():
        if line.startswith("SigIgn:"):
            return bool(int(line.split()[1], 16) & (1 << (signal.SIGINT - 1)))
    return False


def ctrl_c_as_the_pool_starts(command: list[str], workers: int) -> tuple[int, str]:
    """Run ``command``; once it has spawned ``workers`` processes, and while they are still importing,
    send SIGINT to its whole process group. Returns its exit code and everything it wrote to stderr."""
    # A terminal starts a command with Ctrl-C at its default; the test process may be ignoring it (a
    # run started as a background job of a non-interactive shell is; no test was found to leave it so),
    # and an ignored SIGINT is inherited, so the command would never hear it.
    child = subprocess.Popen(
        command,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
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
        # start-up data (the policy's weights among them): a fixed wait (0.2 s, then 1 s) can be too
        # short on a loaded machine, so wait until the parent listens again.
        while ignores_ctrl_c(child.pid):
            assert child.poll() is None and time.monotonic() < deadline, "".join(stderr)
            time.sleep(0.02)
        os.killpg(child.pid, signal.SIGINT)
        code = child.wait(timeout=STOP_TIMEOUT_S)
    finally:
        child.kill()
    reader.join(timeout=10)
    return code, "".join(stderr)
