"""Finding a process's multiprocessing children, for tests that stop or wait for them."""

from __future__ import annotations

from pathlib import Path


def spawned_children(pid: int) -> list[int]:
    """``pid``'s children started by multiprocessing's spawn, read from /proc (the resource tracker is not one)."""
    children = []
    for thread in Path(f"/proc/{pid}/task").iterdir():
        children += [int(child) for child in (thread / "children").read_text().split()]
    return [child for child in children if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes()]
