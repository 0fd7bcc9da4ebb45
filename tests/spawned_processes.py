"""Finding a process's multiprocessing children, for tests that stop or wait for them."""

from __future__ import annotations

from pathlib import Path


def _read(path: Path) -> bytes:
    """A /proc file's content, or nothing if its thread or process ended while we looked."""
    try:
        return path.read_bytes()
    except OSError:
        return b""


def spawned_children(pid: int) -> list[int]:
    """``pid``'s children started by multiprocessing's spawn, read from /proc (the resource tracker is not one).

    Short-lived children (a ``find_library`` subprocess during an import) and threads may end between
    listing and reading; those are skipped, not an error.
    """
    children = []
    for thread in Path(f"/proc/{pid}/task").iterdir():
        children += [int(child) for child in _read(thread / "children").split()]
    return [child for child in children if b"spawn_main" in _read(Path(f"/proc/{child}/cmdline"))]
