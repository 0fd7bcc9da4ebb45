"""Copies of the packages for the registry tests: a copy before and a copy after a new kind or family is added,
and the files that differ between them, so a test can hold an addition to "one module and one line"."""

from __future__ import annotations

import filecmp
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def changed_files(before: Path, after: Path) -> list[str]:
    """Paths (relative) that differ between two trees: added, removed or changed files."""
    found: list[str] = []

    def walk(comparison: filecmp.dircmp[str], prefix: Path) -> None:
        found.extend(str(prefix / name) for name in comparison.left_only + comparison.right_only)
        found.extend(str(prefix / name) for name in comparison.diff_files)
        for name, sub in comparison.subdirs.items():
            walk(sub, prefix / name)

    walk(filecmp.dircmp(before, after, ignore=["__pycache__"]), Path())
    return sorted(found)


def copies_before_and_after(
    before: Path, after: Path, packages: Sequence[str], addition: Callable[[Path], None]
) -> tuple[Path, Path]:
    """``packages`` and the dispatcher copied into ``before`` and ``after``, then ``addition`` made to ``after``."""
    for tree in (before, after):
        for package in packages:
            shutil.copytree(ROOT / package, tree / package, ignore=shutil.ignore_patterns("__pycache__"))
        shutil.copy(ROOT / "kuka_curriculum.py", tree / "kuka_curriculum.py")
    addition(after)
    return before, after
