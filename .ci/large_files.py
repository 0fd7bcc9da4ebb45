"""Refuse tracked files over 5 MB unless .large-files-allowlist names them, so the repository stays light.

Sizes are those of the blobs in git's index: what the next commit would hold, whatever the working tree
has since. The allowlist holds one path per line (``#`` starts a comment); it lists the big files that
were already committed when this check began, so that nothing had to be deleted for it.

    python .ci/large_files.py [--root DIR] [--limit BYTES]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

LIMIT_BYTES = 5_000_000
ALLOWLIST = ".large-files-allowlist"


def tracked_sizes(root: Path) -> dict[str, int]:
    """Every path in the index with its blob's size in bytes (submodules, which have no blob, left out)."""
    listing = subprocess.run(
        ["git", "ls-files", "--stage", "-z"], cwd=root, capture_output=True, check=True
    ).stdout.decode()
    objects: dict[str, list[str]] = {}
    for entry in filter(None, listing.split("\0")):
        meta, path = entry.split("\t", 1)
        mode, object_id, _stage = meta.split()
        if mode != "160000":
            objects.setdefault(object_id, []).append(path)
    batch = subprocess.run(
        ["git", "cat-file", "--batch-check=%(objectname) %(objectsize)"],
        cwd=root, input="\n".join(objects).encode(), capture_output=True, check=True,
    ).stdout.decode()  # fmt: skip
    sizes: dict[str, int] = {}
    for line in batch.splitlines():
        object_id, size = line.split()
        sizes.update(dict.fromkeys(objects[object_id], int(size)))
    return sizes


def allowed(root: Path) -> set[str]:
    path = root / ALLOWLIST
    if not path.is_file():
        return set()
    return {entry for line in path.read_text().splitlines() if (entry := line.split("#")[0].strip())}


def oversized(root: Path, limit: int = LIMIT_BYTES) -> dict[str, int]:
    """The tracked files over ``limit`` bytes that the allowlist does not name."""
    permitted = allowed(root)
    return {path: size for path, size in sorted(tracked_sizes(root).items()) if size > limit and path not in permitted}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1])
    parser.add_argument("--limit", type=int, default=LIMIT_BYTES, help="bytes (default: %(default)s)")
    args = parser.parse_args(argv)
    found = oversized(args.root, args.limit)
    if found:
        print(f"Tracked files over {args.limit:,} bytes that {ALLOWLIST} does not list:", file=sys.stderr)
        print("\n".join(f"  {path} ({size:,} bytes)" for path, size in found.items()), file=sys.stderr)
        print("Keep them out of git (compress or regenerate them; a results page says how).", file=sys.stderr)
        return 1
    print(f"no tracked file over {args.limit:,} bytes outside {ALLOWLIST}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
