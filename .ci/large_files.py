"""Keep the repository light: no tracked file over 5 MB, and tracked files outside ``models/`` within a
total, so a clone carries code, docs and the write-ups' results rather than raw experiment output.

Sizes are those of the blobs in git's index: what the next commit would hold, whatever the working tree
has since. ``models/`` holds the shipped policies, which the total leaves out (each still counts against
the per-file limit). A run's raw files (teacher databases, logs, raw metrics) are git-ignored; the
results pages say which command regenerates them.

    python .ci/large_files.py [--root DIR] [--limit BYTES] [--total-limit BYTES]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

LIMIT_BYTES = 5_000_000
TOTAL_LIMIT_BYTES = 30_000_000
"""Issue 57's bound on the tree outside models/: the write-ups' results, plots, evaluation-only final
checkpoints and compressed metrics, beside the code and docs."""
EXCLUDED_FROM_TOTAL = "models/"


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


def oversized(sizes: dict[str, int], limit: int = LIMIT_BYTES) -> dict[str, int]:
    """The tracked files over ``limit`` bytes."""
    return {path: size for path, size in sorted(sizes.items()) if size > limit}


def total_outside_models(sizes: dict[str, int]) -> int:
    return sum(size for path, size in sizes.items() if not path.startswith(EXCLUDED_FROM_TOTAL))


def largest(sizes: dict[str, int], count: int = 5) -> list[tuple[str, int]]:
    return sorted(sizes.items(), key=lambda item: item[1], reverse=True)[:count]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1])
    parser.add_argument("--limit", type=int, default=LIMIT_BYTES, help="bytes per file (default: %(default)s)")
    parser.add_argument(
        "--total-limit", type=int, default=TOTAL_LIMIT_BYTES,
        help=f"bytes in all outside {EXCLUDED_FROM_TOTAL} (default: %(default)s)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    sizes = tracked_sizes(args.root)
    failed = False
    if found := oversized(sizes, args.limit):
        print(f"Tracked files over {args.limit:,} bytes:", file=sys.stderr)
        print("\n".join(f"  {path} ({size:,} bytes)" for path, size in found.items()), file=sys.stderr)
        failed = True
    total = total_outside_models(sizes)
    if total > args.total_limit:
        outside = {path: size for path, size in sizes.items() if not path.startswith(EXCLUDED_FROM_TOTAL)}
        print(
            f"Tracked files outside {EXCLUDED_FROM_TOTAL} total {total:,} bytes, over {args.total_limit:,}; "
            "the largest:",
            file=sys.stderr,
        )
        print("\n".join(f"  {path} ({size:,} bytes)" for path, size in largest(outside)), file=sys.stderr)
        failed = True
    if failed:
        print("Keep them out of git (compress or regenerate them; a results page says how).", file=sys.stderr)
        return 1
    print(f"no tracked file over {args.limit:,} bytes; {total:,} bytes outside {EXCLUDED_FROM_TOTAL}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
