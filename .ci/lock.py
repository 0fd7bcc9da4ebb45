"""Keep the lock files (requirements.txt, requirements-dev.txt) honest about pyproject.toml.

``stamp`` writes, after ``pip-compile``, a header line with a hash of what the locks were compiled from:
the dependency lists of pyproject.toml and the pins of constraints.txt. ``check`` (``make lock-check``)
fails when that hash no longer matches, or when a requirement of pyproject.toml has no pin in its lock or a
pin it does not accept. It reads files only: no index, no network, well under a second.

    python .ci/lock.py stamp [--root DIR]
    python .ci/lock.py check [--root DIR]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

PROJECT = "kuka-curriculum"
CONSTRAINTS = "constraints.txt"
HEADER = "# lock inputs sha256: "
"""The stamp's prefix: the hash follows it on one line at the top of each lock file."""
PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==(\S+)")
PROJECT_ENTRY = re.compile(rf"^{PROJECT}\b", re.IGNORECASE)


@dataclass(frozen=True)
class Lock:
    """A lock file and the extras of pyproject.toml it is compiled for (besides the core dependencies)."""

    path: str
    extras: tuple[str, ...]


LOCKS = (Lock("requirements.txt", ("stack",)), Lock("requirements-dev.txt", ("dev",)))


def constraint_lines(root: Path) -> list[str]:
    """constraints.txt's requirements, without comments and blank lines."""
    lines = (line.split("#")[0].strip() for line in (root / CONSTRAINTS).read_text().splitlines())
    return [line for line in lines if line]


def inputs_digest(root: Path) -> str:
    """A hash of everything the locks are compiled from, independent of the files' formatting and comments."""
    project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    inputs = {
        "requires-python": project.get("requires-python", ""),
        "dependencies": project.get("dependencies", []),
        "optional-dependencies": project.get("optional-dependencies", {}),
        "constraints": constraint_lines(root),
    }
    return hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()


def requirements(root: Path, extras: tuple[str, ...]) -> list[Requirement]:
    """The core dependencies and the extras' requirements, with the project's own extras expanded
    (``dev`` names ``kuka-curriculum[video,sb3,rllib]``), for this interpreter's markers."""
    project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    optional: dict[str, list[str]] = project.get("optional-dependencies", {})
    found: list[Requirement] = []
    pending, seen = list(extras), set()
    for text in project.get("dependencies", []):
        found.append(Requirement(text))
    while pending:
        extra = pending.pop()
        if extra in seen:
            continue
        seen.add(extra)
        for text in optional[extra]:
            requirement = Requirement(text)
            if canonicalize_name(requirement.name) == PROJECT:
                pending.extend(requirement.extras)
            else:
                found.append(requirement)
    return [r for r in found if r.marker is None or r.marker.evaluate({"extra": ""})]


def pins(lock_text: str) -> dict[str, Version]:
    return {canonicalize_name(m[1]): Version(m[2]) for line in lock_text.splitlines() if (m := PIN.match(line))}


def recorded_digest(lock_text: str) -> str | None:
    for line in lock_text.splitlines():
        if line.startswith(HEADER):
            return line.removeprefix(HEADER).strip()
    return None


def problems(root: Path) -> list[str]:
    """Every way the locks disagree with pyproject.toml and constraints.txt; empty when they agree."""
    found: list[str] = []
    digest = inputs_digest(root)
    constraints = [Requirement(line) for line in constraint_lines(root)]
    for lock in LOCKS:
        path = root / lock.path
        if not path.is_file():
            found.append(f"{lock.path} is missing")
            continue
        text = path.read_text()
        if recorded_digest(text) != digest:
            found.append(f"{lock.path} was compiled from another pyproject.toml or {CONSTRAINTS}")
        pinned = pins(text)
        for requirement in [*requirements(root, lock.extras), *constraints]:
            version = pinned.get(canonicalize_name(requirement.name))
            if version is None:
                found.append(f"{lock.path} pins nothing for {requirement}")
            elif not requirement.specifier.contains(version, prereleases=True):
                found.append(f"{lock.path} pins {requirement.name}=={version}, outside {requirement}")
        if any(PROJECT_ENTRY.match(line) for line in text.splitlines()):
            found.append(f"{lock.path} holds the project itself; `make lock` leaves it out")
        unhashed = [line for line in text.splitlines() if PIN.match(line) and not line.rstrip().endswith("\\")]
        found.extend(f"{lock.path} has no hash for {line.split()[0]}" for line in unhashed)
    return found


def without_project(lines: list[str]) -> list[str]:
    """The lines less the project's own entry (``kuka-curriculum @ file:///...``, and its comments):
    pip-compile writes it for an extra that names the project's other extras, but the lock pins only
    dependencies (the project is installed from the checkout), and a local path holds on no other machine."""
    kept: list[str] = []
    skipping = False
    for line in lines:
        if not line.startswith(" "):
            skipping = PROJECT_ENTRY.match(line) is not None
            while skipping and kept and kept[-1].startswith("# ") and "hash" in kept[-1]:
                kept.pop()  # pip-compile's warning that the entry has no hash
        if not skipping:
            kept.append(line)
    return kept


def stamp(root: Path) -> None:
    """Put the inputs' hash on the line after pip-compile's header (replacing an earlier stamp), and drop
    the project's own entry; a lock not compiled yet is left for the next stamp."""
    digest = inputs_digest(root)
    for lock in LOCKS:
        path = root / lock.path
        if not path.is_file():
            continue
        lines = [line for line in without_project(path.read_text().splitlines()) if not line.startswith(HEADER)]
        header_end = next(index for index, line in enumerate(lines) if not line.startswith("#"))
        lines.insert(header_end, f"{HEADER}{digest}")
        path.write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("action", choices=("stamp", "check"))
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1])
    args = parser.parse_args(argv)
    if args.action == "stamp":
        stamp(args.root)
        return 0
    found = problems(args.root)
    if found:
        print("The lock files disagree with pyproject.toml; run `make lock` and commit the result:", file=sys.stderr)
        print("\n".join(f"  {problem}" for problem in found), file=sys.stderr)
        return 1
    print(f"lock files agree with pyproject.toml and {CONSTRAINTS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
