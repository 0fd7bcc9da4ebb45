"""The store maps typed records to its rows and back: what goes in through its write methods comes
back out of its read methods, field by field, after a restart, in the database's own columns."""

from __future__ import annotations

import asyncio
import dataclasses
import sqlite3
from pathlib import Path

import numpy as np

from teacher_service.store import (
    AwaitedTask,
    NewResult,
    NewTask,
    Store,
    StoredCurriculum,
    StoredFit,
    StoredResult,
    StoredSnapshot,
    StoredTask,
    TeacherSnapshot,
)

CURRICULUM = StoredCurriculum(id=7, name="records", spec='{"teacher": "random"}', created_at=1.5)
TASKS = [
    NewTask(index=0, task={"x": 0.25}, results_seen=0, issued_at=2.0),
    NewTask(index=1, task={"x": 0.75}, results_seen=0, issued_at=2.0),
    NewTask(index=2, task={"x": 0.5}, results_seen=1, issued_at=3.0),
]
RESULT = NewResult(task_index=1, reward=0.5, success=True, length=40, received_at=4.0)
FIT = StoredFit(index=3, tasks_drawn=11, results_seen=5, started_at=5.0, finished_at=6.5, error=None, model='{"m": 1}')
HISTORY = np.arange(6.0).reshape(3, 2)


def _snapshot(tasks_issued: int, issued_index_end: int) -> TeacherSnapshot:
    return TeacherSnapshot(
        results_seen=1,
        last_task_index=1,
        tasks_issued=tasks_issued,
        issued_index_end=issued_index_end,
        outstanding=[0, 2],
        fits_waiting=[3],
        teacher={"kind": "random", "state": {}},
        history=HISTORY,
        history_from=0,
        taken_at=7.0,
    )


def _write_live(path: Path) -> None:
    """Write every kind of record the way a running service does: grouped on its event loop."""
    store = Store(path)

    async def write() -> None:
        store.start(asyncio.get_running_loop())
        await store.add_curriculum(CURRICULUM)
        await store.add_tasks(CURRICULUM.id, TASKS)
        await store.add_results(CURRICULUM.id, [RESULT])
        store.add_fit_later(CURRICULUM.id, FIT)
        store.put_snapshot_later(CURRICULUM.id, _snapshot(tasks_issued=3, issued_index_end=4))

    try:
        asyncio.run(write())
    finally:
        store.close()


def test_records_written_live_read_back_unchanged_after_a_restart(tmp_path: Path) -> None:
    path = tmp_path / "teacher.db"
    _write_live(path)
    store = Store(path)
    try:
        assert store.curricula() == [CURRICULUM]
        assert store.tasks_from(CURRICULUM.id, 1) == [StoredTask(index=1, results_seen=0), StoredTask(2, 1)]
        assert store.last_task_indices(CURRICULUM.id, 2) == [1, 2]
        assert store.last_task_indices(CURRICULUM.id, 9) == [0, 1, 2]
        assert list(store.results(CURRICULUM.id)) == [
            StoredResult(seq=1, task_index=1, task={"x": 0.75}, reward=0.5, success=True, length=40, received_at=4.0)
        ]
        assert store.fits_since(CURRICULUM.id, 5) == [FIT]
        assert store.recent_fits(CURRICULUM.id, 10) == [dataclasses.replace(FIT, model=None)]
        assert store.snapshot(CURRICULUM.id) == StoredSnapshot(
            results_seen=1,
            last_seq=1,
            tasks_issued=3,
            issued_index_end=4,
            outstanding=[0, 2],
            fits_waiting=[3],
            history_rows=3,
            teacher={"kind": "random", "state": {}},
        )
        assert np.array_equal(store.history(CURRICULUM.id, 3), HISTORY)
        assert list(store.awaited_tasks(CURRICULUM.id, [0], 2)) == [
            AwaitedTask(index=0, task={"x": 0.25}, issued_at=2.0),
            AwaitedTask(index=2, task={"x": 0.5}, issued_at=3.0),
        ]
    finally:
        store.close()
    with sqlite3.connect(path) as db:  # the columns keep their names, whatever the records call them
        assert db.execute("SELECT tasks_sampled, results_seen FROM fits").fetchall() == [(11, 5)]
        assert db.execute("SELECT tasks_issued, issued_through FROM snapshots").fetchall() == [(3, 4)]


def test_a_replay_stores_its_rerun_fits_and_snapshot_in_one_write(tmp_path: Path) -> None:
    path = tmp_path / "teacher.db"
    _write_live(path)
    rerun = dataclasses.replace(FIT, error="install failed: ValueError: no", model=None)
    store = Store(path)
    try:
        store.save_replayed_now(CURRICULUM.id, [rerun], _snapshot(tasks_issued=3, issued_index_end=5))
        assert store.fits_since(CURRICULUM.id, 0) == [rerun]
        snapshot = store.snapshot(CURRICULUM.id)
        assert snapshot is not None and snapshot.issued_index_end == 5
    finally:
        store.close()
