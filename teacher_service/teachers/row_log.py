"""A teacher's append-only history, of which only a bounded tail stays in memory.

Rows are numbered from the first result on and never change once written, so a store can append
them in chunks. Two parties decide which rows may go: the teacher's algorithm (``needed_from``,
the oldest row it will read again) and the store (``release``: rows it has written and will not
ask for again). Rows before both are dropped when the array fills up; a copy replaces the array,
so views handed out earlier (to a build or fit running elsewhere) keep their rows.
"""

from __future__ import annotations

import numpy as np


class RowLog:
    """Float64 rows addressed by their number since the first; only rows from ``first`` are held."""

    def __init__(self, width: int, capacity: int) -> None:
        self.width = width
        self._capacity = max(capacity, 1)
        self._rows = np.empty((self._capacity, width))
        self.first = 0
        """The oldest row held."""
        self.size = 0
        """Rows written since the first (held or not)."""
        self.needed_from = 0
        """The oldest row the teacher's algorithm will read again; it only moves forward."""
        self._released = 0

    @property
    def held(self) -> int:
        return self.size - self.first

    def release(self, before: int) -> None:
        """Rows before ``before`` are stored elsewhere and will not be asked for again."""
        self._released = max(self._released, min(before, self.size))

    def append(self, values: np.ndarray | tuple[float, ...]) -> None:
        if self.size - self.first == len(self._rows):
            self._make_room()
        self._rows[self.size - self.first] = values
        self.size += 1

    def view(self, start: int, stop: int | None = None) -> np.ndarray:
        """Rows ``start`` to ``stop`` (default: the last), as a view that never changes."""
        stop = self.size if stop is None else stop
        if not self.first <= start <= stop <= self.size:
            raise ValueError(f"rows {start} to {stop} are not held: rows {self.first} to {self.size} are")
        view: np.ndarray = self._rows[start - self.first : stop - self.first]
        return view

    def copy(self, start: int) -> np.ndarray:
        rows: np.ndarray = self.view(start).copy()
        return rows

    def load(self, rows: np.ndarray, first: int, size: int) -> None:
        """Hold ``rows`` as rows ``first`` to ``size`` (restoring from a store)."""
        if len(rows) != size - first:
            raise ValueError(f"rows {first} to {size} are {size - first} rows, got {len(rows)}")
        if len(rows) and (rows.ndim != 2 or rows.shape[1] != self.width):
            raise ValueError(f"history rows must have {self.width} columns, got shape {rows.shape}")
        self._rows = np.empty((max(2 * len(rows), self._capacity), self.width))
        self._rows[: len(rows)] = rows
        self.first, self.size = first, size
        self.needed_from = self._released = first

    def _make_room(self) -> None:
        """Drop the rows neither party needs, into a fresh array twice the size of those kept
        when that would be more than half full."""
        cut = max(self.first, min(self.needed_from, self._released))
        kept = self._rows[cut - self.first : self.size - self.first]
        grown = np.empty((max(2 * len(kept), self._capacity), self.width))
        grown[: len(kept)] = kept
        self._rows, self.first = grown, cut
