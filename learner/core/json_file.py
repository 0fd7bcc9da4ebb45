"""JSON files written whole or not at all, indented for reading, with each list of numbers on one line."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any

_SCALAR = r"(?:-?\d[\d.eE+-]*|-?Infinity|NaN|true|false|null)"
_SCALAR_LIST = re.compile(rf"\[\n\s*({_SCALAR}(?:,\n\s*{_SCALAR})*)\n\s*\]")
"""An array ``json.dumps(indent=2)`` spread over lines whose items are all numbers, booleans or nulls; the
line breaks keep it from matching inside a string, where JSON escapes them."""


def dumps(data: dict[str, Any]) -> str:
    """Indented JSON where a list of numbers takes one line, not one per item: an evaluation's per-episode
    columns are a few lines to read and to diff, and a third of the bytes in the archived runs."""
    return _SCALAR_LIST.sub(_on_one_line, json.dumps(data, indent=2))


def _on_one_line(match: re.Match[str]) -> str:
    return "[" + ", ".join(item.strip() for item in match.group(1).split(",")) + "]"


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write through a temporary file, so an interrupted write never leaves half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    partial.write_text(dumps(data) + "\n", encoding="utf-8")
    os.replace(partial, path)
