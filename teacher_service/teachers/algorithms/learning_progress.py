"""ALP-GMM's learning-progress history (Portelas et al. 2019): every result as a row, and for a new
task the nearest earlier one, whose reward the absolute learning progress (ALP) is measured from.
Pure numpy and scipy; the teacher adapter (``teachers.alp_gmm``) feeds it results, fits mixtures to
its rows (``teachers.mixture``) and saves it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import cast

import numpy as np
from scipy.spatial import cKDTree

from teacher_service.teachers.base import BuildJob
from teacher_service.teachers.row_log import RowLog

MIN_HISTORY_FOR_ALP = 6
"""ALP is 0 until this many earlier tasks exist, as in the reference code."""

TREE_GROWTH = 256
"""Once the tree is large, it is rebuilt every 1/TREE_GROWTH of its rows rather than every
``buffer_size``. Per result that costs a scan of up to two such intervals on the event loop
(~12 ns a row) plus a share of a build on a thread (~0.5 s at 1M rows); at 1M rows, an interval of
~3,900 keeps both near 0.1 ms, and leaves a build seconds to finish before it is needed."""


@dataclass(frozen=True)
class NearestTree:
    """A k-d tree over the first occurrence of each position among some history rows."""

    tree: cKDTree
    rewards: np.ndarray
    """The reward of each point in the tree."""


def build_tree(rows: np.ndarray) -> NearestTree:
    """A k-d tree over ``rows`` (a view of history rows, which never change), repeats left out:
    thousands of identical points (the hardest task, repeated) cannot be split and would fill one
    leaf that every query landing there compares against (12 ms a query at 200,000 repeats, 16 us
    without them). scipy builds the tree without holding the GIL, so a thread can do it while the
    event loop answers requests."""
    firsts = np.flatnonzero(rows[:, -1] == 0.0)
    return NearestTree(cKDTree(rows[firsts, :-3]), rows[firsts, -3].copy())


@dataclass
class NearestTreeBuild:
    size: int
    job: BuildJob
    tree: NearestTree | None = None
    handed_out: bool = False


class ProgressHistory:
    """Every result as a row (task features, reward, ALP, whether an earlier row has the same
    features), and the nearest earlier task among the last ``window`` rows or so.

    Older tasks sit in a k-d tree (each position once, at its first row), newer ones are scanned
    directly. Which tasks the tree holds depends only on the number of rows: at each checkpoint
    (every ``buffer_size`` rows, or every 1/TREE_GROWTH of the tree's rows once that is more) a
    tree over the last ``window`` rows so far is requested as a ``BuildJob``, and it replaces the
    current tree at the next checkpoint. The build has a whole interval to run off the event loop,
    and whoever built it (a thread, or this class itself when the output has not come back in time,
    as in a replay), the switch happens at the same row. Ties between equidistant tasks go to the
    tree, and within the scan to the earliest row, so the answers never depend on timing, and a
    repeated task is always compared with its first row while that row is in the window (a
    position whose first row has left it is left out of the tree until it is drawn again).

    Rows older than the tree's window are dropped once stored (``RowLog``), so memory stays
    bounded by the window whatever the number of results.
    """

    def __init__(self, dims: int, buffer_size: int, window: int) -> None:
        self.dims = dims
        self._buffer_size = buffer_size
        self._window = window
        self.log = RowLog(dims + 3, 2 * buffer_size)
        self._tree: NearestTree | None = None
        self._tree_size = 0
        self._next_checkpoint = buffer_size
        self._build: NearestTreeBuild | None = None

    @property
    def size(self) -> int:
        return self.log.size

    def alps(self, start: int) -> np.ndarray:
        values: np.ndarray = self.log.view(start)[:, self.dims + 1].copy()
        return values

    def fit_points(self, start: int, stop: int) -> np.ndarray:
        """(task features, ALP) of rows ``start`` to ``stop``: the points a mixture is fitted to."""
        rows = self.log.view(start, stop)
        return np.concatenate([rows[:, : self.dims], rows[:, self.dims + 1 : self.dims + 2]], axis=1)

    def nearest(self, point: np.ndarray) -> tuple[float, float]:
        """Distance to the nearest earlier task, and its reward; (inf, nan) for an empty history."""
        distance, reward = np.inf, np.nan
        if self._tree is not None:
            # One point, so scalars; the stubs also allow the arrays a batch of points would give.
            distance, index = cast("tuple[float, np.intp]", self._tree.tree.query(point))
            reward = self._tree.rewards[index]
        if self.size > self._tree_size:
            recent = self.log.view(self._tree_size)
            offsets = recent[:, : self.dims] - point
            squared = np.einsum("ij,ij->i", offsets, offsets)
            nearest = int(np.argmin(squared))
            if math.sqrt(squared[nearest]) < distance:
                distance, reward = math.sqrt(squared[nearest]), recent[nearest, self.dims]
        return float(distance), float(reward)

    def add(self, features: np.ndarray, reward: float, alp: float, repeat: bool) -> None:
        self.log.append(np.concatenate([features, (reward, alp, float(repeat))]))
        if self.size == self._next_checkpoint:
            if self._build is not None:
                self._switch_to(self._build)
            self._request_build()

    def pending_build(self) -> BuildJob | None:
        if self._build is None or self._build.handed_out:
            return None
        self._build.handed_out = True
        return self._build.job

    def adopt(self, job: BuildJob, tree: NearestTree) -> None:
        if self._build is not None and self._build.job is job:
            self._build.tree = tree

    def restore(self, rows: np.ndarray, first: int, size: int) -> None:
        """Take ``rows`` as history rows ``first`` to ``size``, with the tree and pending build a
        live run had there (``first`` is at most the tree's window start, as ``kept_from`` said)."""
        self.log.load(rows, first, size)
        passed = [0, 0]  # the last two checkpoints at or before the last row
        while self._next_checkpoint <= self.size:
            passed = [passed[1], self._next_checkpoint]
            self._next_checkpoint = self._advance(self._next_checkpoint)
        if passed[0]:
            self._switch_to(NearestTreeBuild(passed[0], self._tree_job(passed[0], passed[1])))
        if passed[1]:
            self._build = NearestTreeBuild(passed[1], self._tree_job(passed[1], self._next_checkpoint))

    @property
    def kept_from(self) -> int:
        """The oldest row a restore needs: the start of the current tree's window."""
        return self.log.needed_from

    def _window_start(self, size: int) -> int:
        return max(0, size - self._window)

    def _advance(self, checkpoint: int) -> int:
        return checkpoint + max(self._buffer_size, min(checkpoint, self._window) // TREE_GROWTH)

    def _request_build(self) -> None:
        self._next_checkpoint = self._advance(self.size)
        self._build = NearestTreeBuild(self.size, self._tree_job(self.size, self._next_checkpoint))

    def _tree_job(self, size: int, needed_at: int) -> BuildJob:
        return BuildJob(needed_at, functools.partial(build_tree, self.log.view(self._window_start(size), size)))

    def _switch_to(self, build: NearestTreeBuild) -> None:
        self._tree = build.tree if build.tree is not None else build.job.run()
        self._tree_size = build.size
        self.log.needed_from = self._window_start(build.size)
