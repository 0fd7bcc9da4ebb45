"""The persistence layer: SQLite storage for curricula, issued tasks, accepted results, fits and
teacher snapshots. It owns every SQL string and the mapping between rows and typed records; the
rest of the service hands it records (``NewTask``, ``NewResult``, ``StoredFit``,
``TeacherSnapshot``) and gets records back, never rows or SQL.

Every write is committed before the request that made it is answered. Writes are group-committed
on the event loop: whatever the loop queued while handling one round of ready requests goes into
one transaction, committed right after that round, so a disk sync is shared by every request in
it. (A writer thread was measured and rejected: each SQLite call hands the GIL back and forth with
a busy event loop, and the waits swamp the commits. So was a thread for the ``COMMIT`` alone, the
statements staying on the loop: at 1,000 simulated workers it cost the main process 12 to 16% more
CPU per result and raised p99 by half to nearly double, the results page's "A fleet on one service".)
Writes complete, and their ``on_commit`` callbacks run, in the order they were submitted: the
teachers see results in exactly the order they are stored, which is the order a replay feeds them back.
The one exception is a fit's record that a full disk refused: nobody waits for it and nothing else
can bring it back, so it is tried again with every later commit, and at least every ``RETRY_S``
seconds, until it lands (a fit's row says where it was installed, so its place in the table does
not matter).

What a restart reads (schema version 3): per curriculum, its newest snapshot (one row: the
teacher's exported state, the service's counters and awaited task indices, and the sequence
number of the last result it had learned), the teacher's append-only history as chunks of float64
rows written with the snapshots, and only the tasks, results and fits stored after the snapshot.
Fit rows carry the fitted model, so no installed fit is ever computed twice. A version-1 database
gains the new tables and columns in place; its first start replays its whole history once.
Version 3 adds each result's optional ``score`` (the level kinds'); older rows read as having none.
"""

from __future__ import annotations

import asyncio
import json
import logging
import sqlite3
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from common.client.task_space import Task

log = logging.getLogger(__name__)

RETRY_S = 1.0
"""How long a refused record that must land waits, at most, before it is tried again."""

SCHEMA_VERSION = 3
_SCHEMA_V1 = """
CREATE TABLE curricula (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    spec TEXT NOT NULL,
    created_at REAL NOT NULL
);
CREATE TABLE tasks (
    curriculum_id INTEGER NOT NULL REFERENCES curricula(id),
    task_index INTEGER NOT NULL,
    params TEXT NOT NULL,
    results_seen INTEGER NOT NULL,
    issued_at REAL NOT NULL,
    PRIMARY KEY (curriculum_id, task_index)
) WITHOUT ROWID;
CREATE TABLE results (
    seq INTEGER PRIMARY KEY,
    curriculum_id INTEGER NOT NULL,
    task_index INTEGER NOT NULL,
    reward REAL NOT NULL,
    success INTEGER,
    length INTEGER,
    received_at REAL NOT NULL,
    UNIQUE (curriculum_id, task_index),
    FOREIGN KEY (curriculum_id, task_index) REFERENCES tasks(curriculum_id, task_index)
);
CREATE TABLE fits (
    curriculum_id INTEGER NOT NULL REFERENCES curricula(id),
    fit_index INTEGER NOT NULL,
    tasks_sampled INTEGER NOT NULL,
    results_seen INTEGER NOT NULL,
    started_at REAL NOT NULL,
    finished_at REAL NOT NULL,
    error TEXT,
    PRIMARY KEY (curriculum_id, fit_index)
) WITHOUT ROWID;
"""
_MIGRATE_V1_TO_V2 = """
ALTER TABLE fits ADD COLUMN model TEXT;
CREATE INDEX results_by_curriculum ON results (curriculum_id, seq);
CREATE TABLE snapshots (
    curriculum_id INTEGER PRIMARY KEY REFERENCES curricula(id),
    results_seen INTEGER NOT NULL,
    last_seq INTEGER NOT NULL,
    tasks_issued INTEGER NOT NULL,
    issued_through INTEGER NOT NULL,
    outstanding TEXT NOT NULL,
    fits_waiting TEXT NOT NULL,
    history_rows INTEGER NOT NULL,
    teacher TEXT NOT NULL,
    taken_at REAL NOT NULL
);
CREATE TABLE history_chunks (
    curriculum_id INTEGER NOT NULL REFERENCES curricula(id),
    first_row INTEGER NOT NULL,
    row_count INTEGER NOT NULL,
    width INTEGER NOT NULL,
    data BLOB NOT NULL,
    PRIMARY KEY (curriculum_id, first_row)
);
"""
_MIGRATE_V2_TO_V3 = """
ALTER TABLE results ADD COLUMN score REAL;
"""
_MIGRATIONS = {0: _SCHEMA_V1, 1: _MIGRATE_V1_TO_V2, 2: _MIGRATE_V2_TO_V3}
"""The script that takes a database from each version to the next."""

HISTORY_CHUNK_ROWS = 65_536
"""Most history rows in one chunk, so the first snapshot of a long replay is not one huge blob."""

_INSERT_CURRICULUM = "INSERT INTO curricula (id, name, spec, created_at) VALUES (?, ?, ?, ?)"
_INSERT_TASK = "INSERT INTO tasks (curriculum_id, task_index, params, results_seen, issued_at) VALUES (?, ?, ?, ?, ?)"
_INSERT_RESULT = (
    "INSERT INTO results (curriculum_id, task_index, reward, success, length, received_at, score)"
    " VALUES (?, ?, ?, ?, ?, ?, ?)"
)
_INSERT_FIT = (  # REPLACE: a restart records again a fit it ran because the live row was missing or had no model
    "INSERT OR REPLACE INTO fits"
    " (curriculum_id, fit_index, tasks_sampled, results_seen, started_at, finished_at, error, model)"
    " VALUES (?, ?, ?, ?, ?, ?, ?, ?)"
)
_PUT_SNAPSHOT = (  # last_seq: the result the teacher learned last; NULL, so refused, if it is not stored
    "INSERT OR REPLACE INTO snapshots (curriculum_id, results_seen, last_seq, tasks_issued, issued_through,"
    " outstanding, fits_waiting, history_rows, teacher, taken_at)"
    " VALUES (?1, ?2, CASE WHEN ?2 = 0 THEN 0"
    " ELSE (SELECT seq FROM results WHERE curriculum_id = ?1 AND task_index = ?3) END, ?4, ?5, ?6, ?7, ?8, ?9, ?10)"
)
_PUT_HISTORY_CHUNK = (
    "INSERT OR REPLACE INTO history_chunks (curriculum_id, first_row, row_count, width, data) VALUES (?, ?, ?, ?, ?)"
)

_DELETE_HISTORY = "DELETE FROM history_chunks WHERE curriculum_id = ?"

_Statements = list[tuple[str, list[tuple[Any, ...]]]]
"""SQL statements, each with the rows to run it on (``executemany``)."""

Callback = Callable[[], object] | None
"""Run once a write is committed (``on_commit``) or refused (``on_abort``); its result is ignored."""


class StoreError(RuntimeError):
    """A write could not be committed; nothing of it is on disk."""


@dataclass(frozen=True)
class StoredCurriculum:
    id: int
    name: str
    spec: str
    created_at: float


@dataclass(frozen=True)
class StoredTask:
    index: int
    results_seen: int
    """Results the teacher had learned from when it drew this task."""


@dataclass(frozen=True)
class StoredResult:
    seq: int
    task_index: int
    task: Task
    reward: float
    success: bool | None
    length: int | None
    received_at: float
    score: float | None = None


@dataclass(frozen=True)
class NewTask:
    """A task being handed out, as the ``tasks`` table stores it."""

    index: int
    task: Task
    results_seen: int
    """Results the teacher had learned from when it drew this task."""
    issued_at: float


@dataclass(frozen=True)
class NewResult:
    """An accepted result being stored; the task it answers is already stored."""

    task_index: int
    reward: float
    success: bool | None
    length: int | None
    received_at: float
    score: float | None = None


@dataclass(frozen=True)
class AwaitedTask:
    """A stored task a restart may still await a result for."""

    index: int
    task: Task
    issued_at: float


@dataclass(frozen=True)
class StoredFit:
    index: int
    tasks_drawn: int
    """Tasks the teacher had drawn (its ``tasks_drawn``) when the fit was installed; the
    ``tasks_sampled`` column."""
    results_seen: int
    started_at: float
    finished_at: float
    error: str | None
    model: str | None = None
    """The fitted model as ``Teacher.export_fit`` JSON; None for a failed fit, or one stored by a
    version-1 service."""


@dataclass(frozen=True)
class TeacherSnapshot:
    """A curriculum's state after its teacher had learned ``results_seen`` results."""

    results_seen: int
    last_task_index: int | None
    """Task answered by the last of those results; the restart replays the results stored after it."""
    tasks_issued: int
    """Tasks handed out (stored) by then."""
    issued_index_end: int
    """One past the highest task index stored by then; tasks from here on were issued later (the
    ``issued_through`` column)."""
    outstanding: list[int]
    """Tasks awaiting a result then (at most ``KC_TASK_WINDOW``)."""
    fits_waiting: list[int]
    """Fits that had fallen due and not come back."""
    teacher: dict[str, Any]
    history: np.ndarray
    """The teacher's history rows not yet stored, the first of them row ``history_from``."""
    history_from: int
    taken_at: float


@dataclass(frozen=True)
class StoredSnapshot:
    results_seen: int
    last_seq: int
    tasks_issued: int
    issued_index_end: int
    outstanding: list[int]
    fits_waiting: list[int]
    history_rows: int
    teacher: dict[str, Any]


def _snapshot_statements(curriculum_id: int, snapshot: TeacherSnapshot) -> _Statements:
    """The write that stores ``snapshot``: it replaces the curriculum's previous one, and appends the
    new history rows, atomically, so the chunks always end where the stored snapshot does. A
    snapshot whose rows start at row 0 holds the whole history (a first one, or one after a
    rebuild from the first result): it replaces every stored chunk."""
    rows = np.ascontiguousarray(snapshot.history, dtype="<f8")
    width = rows.shape[1] if rows.ndim == 2 else 0
    chunks = [
        (curriculum_id, snapshot.history_from + start, len(piece), width, piece.tobytes())
        for start in range(0, len(rows), HISTORY_CHUNK_ROWS)
        if len(piece := rows[start : start + HISTORY_CHUNK_ROWS])
    ]
    row = (
        curriculum_id,
        snapshot.results_seen,
        snapshot.last_task_index,
        snapshot.tasks_issued,
        snapshot.issued_index_end,
        json.dumps(snapshot.outstanding),
        json.dumps(snapshot.fits_waiting),
        snapshot.history_from + len(rows),
        json.dumps(snapshot.teacher),
        snapshot.taken_at,
    )
    replaced = [(_DELETE_HISTORY, [(curriculum_id,)])] if snapshot.history_from == 0 else []
    return [*replaced, (_PUT_HISTORY_CHUNK, chunks), (_PUT_SNAPSHOT, [row])]


_SELECT_RESULTS = (
    "SELECT r.seq, r.task_index, t.params, r.reward, r.success, r.length, r.received_at, r.score"
    " FROM results r JOIN tasks t USING (curriculum_id, task_index)"
)
_FIT_COLUMNS = "fit_index, tasks_sampled, results_seen, started_at, finished_at, error"


def _fit_row(curriculum_id: int, fit: StoredFit) -> tuple[Any, ...]:
    return (
        curriculum_id,
        fit.index,
        fit.tasks_drawn,
        fit.results_seen,
        fit.started_at,
        fit.finished_at,
        fit.error,
        fit.model,
    )


def _result(row: tuple[Any, ...]) -> StoredResult:
    seq, index, params, reward, success, length, received_at, score = row
    return StoredResult(
        seq, index, json.loads(params), reward, None if success is None else bool(success), length, received_at, score
    )


@dataclass
class _Write:
    statements: _Statements
    future: asyncio.Future[None] | None
    on_commit: Callback
    on_abort: Callback
    error: BaseException | None = field(default=None)
    keep_trying: bool = False
    """Tried again until it lands when the disk or the file refused it (SQLite's operational errors:
    full, I/O, read-only); never when its statements were wrong, which they would be again."""


class Store:
    """The service's database. Reads and ``save_replayed_now`` are for startup; once ``start`` has
    run, every write is queued on the event loop thread and group-committed (``add_*``,
    ``put_snapshot_later``)."""

    def __init__(self, path: Path, synchronous: Literal["FULL", "NORMAL"] = "FULL") -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._db = sqlite3.connect(path, isolation_level=None)
        if self._db.execute("PRAGMA journal_mode=WAL").fetchone()[0] != "wal":
            raise StoreError(f"{path}: SQLite could not switch to WAL mode")
        self._db.execute(f"PRAGMA synchronous={synchronous}")
        self._db.execute("PRAGMA foreign_keys=ON")
        self._migrate()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pending: list[_Write] = []
        self._refused: list[_Write] = []
        """Writes that must land, refused by a failed commit: the next commit tries them first."""
        self._retry: asyncio.TimerHandle | None = None
        self.writes_failing: str | None = None
        """Why the last commit failed (a full disk, a read-only file); None once one succeeds."""

    def _migrate(self) -> None:
        """Bring the database up to ``SCHEMA_VERSION``, one version per transaction."""
        version = self._db.execute("PRAGMA user_version").fetchone()[0]
        if version > SCHEMA_VERSION:
            raise StoreError(f"{self.path}: schema version {version}, this service reads version {SCHEMA_VERSION}")
        for step in range(version, SCHEMA_VERSION):
            if step:
                log.info("%s: migrating the schema from version %d to %d", self.path, step, step + 1)
            self._db.executescript(f"BEGIN; {_MIGRATIONS[step]} PRAGMA user_version = {step + 1}; COMMIT;")

    def curricula(self) -> list[StoredCurriculum]:
        rows = self._db.execute("SELECT id, name, spec, created_at FROM curricula ORDER BY id")
        return [StoredCurriculum(*row) for row in rows]

    def snapshot(self, curriculum_id: int) -> StoredSnapshot | None:
        row = self._db.execute(
            "SELECT results_seen, last_seq, tasks_issued, issued_through, outstanding, fits_waiting, history_rows,"
            " teacher FROM snapshots WHERE curriculum_id = ?",
            (curriculum_id,),
        ).fetchone()
        if row is None:
            return None
        results_seen, last_seq, tasks_issued, issued_index_end, outstanding, waiting, history_rows, teacher = row
        return StoredSnapshot(
            results_seen,
            last_seq,
            tasks_issued,
            issued_index_end,
            json.loads(outstanding),
            json.loads(waiting),
            history_rows,
            json.loads(teacher),
        )

    def history(self, curriculum_id: int, rows: int, start: int = 0) -> np.ndarray:
        """History rows ``start`` to ``rows``, from the chunks written with the snapshots."""
        chunks = self._db.execute(
            "SELECT first_row, row_count, width, data FROM history_chunks"
            " WHERE curriculum_id = ? AND first_row < ? AND first_row + row_count > ? ORDER BY first_row",
            (curriculum_id, rows, start),
        ).fetchall()
        if not chunks:
            if rows > start:
                raise StoreError(
                    f"{self.path}: curriculum {curriculum_id} has no history chunks for rows {start} to {rows}"
                )
            return np.empty((0, 0))
        width = chunks[0][2]
        history = np.empty((rows - start, width))
        filled = chunks[0][0]
        if filled > start:
            raise StoreError(
                f"{self.path}: curriculum {curriculum_id}'s history chunks start at row {filled}, not {start}"
            )
        for first_row, row_count, chunk_width, data in chunks:
            if first_row != filled or chunk_width != width or first_row + row_count > rows:
                raise StoreError(
                    f"{self.path}: curriculum {curriculum_id}'s history chunk at row {first_row} "
                    f"({row_count} x {chunk_width}) does not follow row {filled} of {rows} x {width}"
                )
            chunk = np.frombuffer(data, dtype="<f8").reshape(row_count, width)
            skip = max(start - first_row, 0)
            history[first_row + skip - start : first_row + row_count - start] = chunk[skip:]
            filled += row_count
        if filled != rows:
            raise StoreError(
                f"{self.path}: curriculum {curriculum_id}'s history chunks end at row {filled}, not {rows}"
            )
        return history

    def tasks_from(self, curriculum_id: int, first_index: int) -> list[StoredTask]:
        """Issued tasks from ``first_index`` on, in index order."""
        rows = self._db.execute(
            "SELECT task_index, results_seen FROM tasks WHERE curriculum_id = ? AND task_index >= ?"
            " ORDER BY task_index",
            (curriculum_id, first_index),
        )
        return [StoredTask(*row) for row in rows]

    def last_task_indices(self, curriculum_id: int, count: int) -> list[int]:
        """The indices of the last ``count`` stored tasks, in index order."""
        rows = self._db.execute(
            "SELECT task_index FROM tasks WHERE curriculum_id = ? ORDER BY task_index DESC LIMIT ?",
            (curriculum_id, count),
        )
        return [index for (index,) in rows][::-1]

    def result_count(self, curriculum_id: int, after_seq: int = 0) -> int:
        row = self._db.execute(
            "SELECT count(*) FROM results WHERE curriculum_id = ? AND seq > ?", (curriculum_id, after_seq)
        ).fetchone()
        count: int = row[0]
        return count

    def results(self, curriculum_id: int, after_seq: int = 0) -> Iterator[StoredResult]:
        """Accepted results stored after ``after_seq``, in the order the teacher learned from them,
        with the tasks they answer."""
        rows = self._db.execute(
            f"{_SELECT_RESULTS} WHERE r.curriculum_id = ? AND r.seq > ? ORDER BY r.seq", (curriculum_id, after_seq)
        )
        for row in rows:
            yield _result(row)

    def awaited_tasks(self, curriculum_id: int, indices: list[int], first_index: int) -> Iterator[AwaitedTask]:
        """Tasks ``indices`` and every task from ``first_index`` on, each with when it was issued, in
        index order: the tasks a restart may still await results for."""
        lookup = "SELECT task_index, params, issued_at FROM tasks WHERE curriculum_id = ? AND task_index = ?"
        for index in indices:
            row = self._db.execute(lookup, (curriculum_id, index)).fetchone()
            if row is None:
                raise StoreError(f"{self.path}: curriculum {curriculum_id} has no task {index}")
            yield AwaitedTask(row[0], json.loads(row[1]), row[2])
        rows = self._db.execute(
            "SELECT task_index, params, issued_at FROM tasks WHERE curriculum_id = ? AND task_index >= ?"
            " ORDER BY task_index",
            (curriculum_id, first_index),
        )
        for index, params, issued_at in rows:
            yield AwaitedTask(index, json.loads(params), issued_at)

    def answered_tasks(self, curriculum_id: int, indices: list[int]) -> set[int]:
        """Which of these tasks have a stored result (at most ``MAX_RESULTS_PER_REQUEST`` of them)."""
        marks = ", ".join("?" * len(indices))  # placeholders only: the values stay bound parameters
        rows = self._db.execute(
            f"SELECT task_index FROM results WHERE curriculum_id = ? AND task_index IN ({marks})",
            (curriculum_id, *indices),
        )
        return {index for (index,) in rows}

    def recent_results(self, curriculum_id: int, limit: int) -> list[StoredResult]:
        """The last ``limit`` results, oldest first."""
        rows = self._db.execute(
            f"{_SELECT_RESULTS} WHERE r.curriculum_id = ? ORDER BY r.seq DESC LIMIT ?", (curriculum_id, limit)
        ).fetchall()
        return [_result(row) for row in reversed(rows)]

    def fits_since(self, curriculum_id: int, results_seen: int) -> list[StoredFit]:
        """Fits installed (or failed) once the teacher had seen ``results_seen`` results, with their models."""
        rows = self._db.execute(
            f"SELECT {_FIT_COLUMNS}, model FROM fits WHERE curriculum_id = ? AND results_seen >= ? ORDER BY fit_index",
            (curriculum_id, results_seen),
        )
        return [StoredFit(*row) for row in rows]

    def recent_fits(self, curriculum_id: int, limit: int) -> list[StoredFit]:
        """The last ``limit`` fits without their models, oldest first."""
        rows = self._db.execute(
            f"SELECT {_FIT_COLUMNS} FROM fits WHERE curriculum_id = ? ORDER BY fit_index DESC LIMIT ?",
            (curriculum_id, limit),
        ).fetchall()
        return [StoredFit(*row) for row in reversed(rows)]

    def fit_count(self, curriculum_id: int) -> int:
        row = self._db.execute("SELECT count(*) FROM fits WHERE curriculum_id = ?", (curriculum_id,)).fetchone()
        count: int = row[0]
        return count

    def save_replayed_now(self, curriculum_id: int, fits: Sequence[StoredFit], snapshot: TeacherSnapshot) -> None:
        """Store what a start-up replay computed, in one transaction: the fits it ran again (their
        rows replace the stored ones) and the snapshot it took after them. Only before ``start``."""
        fit_rows = [_fit_row(curriculum_id, fit) for fit in fits]
        self._write_now([(_INSERT_FIT, fit_rows), *_snapshot_statements(curriculum_id, snapshot)])

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """From now on, writes are grouped and committed on ``loop``."""
        self._loop = loop

    def add_curriculum(self, curriculum: StoredCurriculum, on_abort: Callback = None) -> asyncio.Future[None]:
        row = (curriculum.id, curriculum.name, curriculum.spec, curriculum.created_at)
        return self._write([(_INSERT_CURRICULUM, [row])], on_abort=on_abort)

    def add_tasks(
        self, curriculum_id: int, tasks: Sequence[NewTask], on_commit: Callback = None
    ) -> asyncio.Future[None]:
        rows = [(curriculum_id, task.index, json.dumps(task.task), task.results_seen, task.issued_at) for task in tasks]
        return self._write([(_INSERT_TASK, rows)], on_commit=on_commit)

    def add_results(
        self, curriculum_id: int, results: Sequence[NewResult], on_commit: Callback = None, on_abort: Callback = None
    ) -> asyncio.Future[None]:
        rows = [
            (
                curriculum_id,
                result.task_index,
                result.reward,
                result.success,
                result.length,
                result.received_at,
                result.score,
            )
            for result in results
        ]
        return self._write([(_INSERT_RESULT, rows)], on_commit=on_commit, on_abort=on_abort)

    def add_fit_later(self, curriculum_id: int, fit: StoredFit) -> None:
        """Record a fit that came back (installed or failed); nobody waits for it, and a full disk
        only delays it: without its row, a replay would find the fit due and never recorded."""
        self._write_later([(_INSERT_FIT, [_fit_row(curriculum_id, fit)])], keep_trying=True)

    def put_snapshot_later(
        self, curriculum_id: int, snapshot: TeacherSnapshot, on_commit: Callback = None, on_abort: Callback = None
    ) -> None:
        """Replace the curriculum's snapshot with ``snapshot``; nobody waits for it."""
        self._write_later(_snapshot_statements(curriculum_id, snapshot), on_commit=on_commit, on_abort=on_abort)

    def _write_now(self, statements: _Statements) -> None:
        """Commit on the spot; only before ``start``, when there is no event loop to group on."""
        if self._loop is not None:
            raise RuntimeError("Store: a write on the spot after Store.start; writes now go through the event loop")
        self._db.execute("BEGIN IMMEDIATE")
        try:
            for sql, rows in statements:
                self._db.executemany(sql, rows)
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    def _write(
        self, statements: _Statements, on_commit: Callback = None, on_abort: Callback = None
    ) -> asyncio.Future[None]:
        """Queue statements for one atomic write; call from the event loop.

        The future resolves once they are committed, after ``on_commit`` ran, or fails with
        ``StoreError`` after ``on_abort`` ran. The callbacks run even when the caller stopped
        awaiting, so bookkeeping never depends on the request surviving; what they return is ignored.
        """
        if self._loop is None:
            raise RuntimeError("Store: a write before Store.start")
        future: asyncio.Future[None] = self._loop.create_future()
        self._queue(_Write(statements, future, on_commit, on_abort))
        return future

    def _write_later(
        self,
        statements: _Statements,
        on_commit: Callback = None,
        on_abort: Callback = None,
        keep_trying: bool = False,
    ) -> None:
        """Queue a write nobody waits for (telemetry, snapshots); a failure is logged, or with
        ``keep_trying`` the write is tried again until it lands (``_Write.keep_trying``). The
        callbacks run as for ``_write``."""
        self._queue(_Write(statements, None, on_commit, on_abort, keep_trying=keep_trying))

    def close(self) -> None:
        """Commit what is queued, then close the database; a record the disk still refuses is lost,
        and said so (a restart runs a fit without its record again)."""
        if self._retry is not None:
            self._retry.cancel()
        self._flush(retry_later=False)
        if self._refused:
            log.error("closing with %d records the disk refused; they are lost", len(self._refused))
        self._db.close()

    def _queue(self, write: _Write) -> None:
        assert self._loop is not None
        if not self._pending:
            self._loop.call_soon(self._flush)
        self._pending.append(write)

    def _flush(self, retry_later: bool = True) -> None:
        group, self._pending, self._refused = self._refused + self._pending, [], []
        if group:
            try:
                self._commit(group)
            finally:
                self._complete(group)
        if self._refused and self._retry is None and retry_later:
            assert self._loop is not None
            self._retry = self._loop.call_later(RETRY_S, self._flush_refused)

    def _flush_refused(self) -> None:
        self._retry = None
        if not self._pending:  # otherwise the flush already due tries them
            self._flush()

    def _commit(self, group: list[_Write]) -> None:
        """Commit the group in one transaction; a write whose statements fail is rolled back alone.

        Any other failure (of BEGIN, a savepoint or COMMIT; SQLite, I/O or anything else) rolls the
        whole group back and fails every write of it: a transaction left open would keep every later
        write from starting, and requests waiting on this group would never be answered.
        """
        try:
            if self._db.in_transaction:  # left open by a failure whose rollback failed too
                self._db.execute("ROLLBACK")
            self._db.execute("BEGIN IMMEDIATE")
            for write in group:
                self._db.execute("SAVEPOINT one_write")
                try:
                    for sql, rows in write.statements:
                        self._db.executemany(sql, rows)
                except Exception as error:
                    if not self._db.in_transaction:
                        raise  # SQLite rolled the whole transaction back (disk full, I/O error)
                    self._db.execute("ROLLBACK TO one_write")
                    write.error = error
                    write.keep_trying &= isinstance(error, sqlite3.OperationalError)
                self._db.execute("RELEASE one_write")
            self._db.execute("COMMIT")
            if self.writes_failing is not None:
                log.warning("writes land again (they had failed: %s)", self.writes_failing)
            self.writes_failing = None
        except BaseException as error:
            reason = _reason(error)
            if reason != self.writes_failing:  # once when it starts: a full disk retries a refused record every second
                log.exception("commit of %d writes failed", len(group))
            self.writes_failing = reason
            self._roll_back()
            for write in group:
                write.error = write.error or error
            if not isinstance(error, Exception):
                raise

    def _roll_back(self) -> None:
        try:
            if self._db.in_transaction:
                self._db.execute("ROLLBACK")
        except sqlite3.Error:
            log.exception("rollback failed; the next write retries it")

    def _complete(self, group: list[_Write]) -> None:
        for write in group:
            if write.error is not None and write.keep_trying:
                write.error = None
                self._refused.append(write)
                continue
            outcome: Exception | None
            if write.error is None:
                callback, outcome = write.on_commit, None
            else:
                callback, outcome = write.on_abort, StoreError(_reason(write.error))
            try:
                if callback is not None:
                    callback()
            except Exception as error:  # a bookkeeping bug must not strand the writes after it
                log.exception("store callback failed")
                outcome = outcome or error
            if write.future is None:
                if outcome is not None:
                    log.error("background write failed: %s", outcome)
            elif not write.future.done():
                if outcome is None:
                    write.future.set_result(None)
                else:
                    write.future.set_exception(outcome)


def _reason(error: BaseException) -> str:
    """Why a write failed, in words for whoever sent it: SQLite's own message says it best
    ("database or disk is full", "attempt to write a readonly database"); anything else is named."""
    if isinstance(error, sqlite3.Error):
        return str(error)
    return f"{type(error).__name__}: {error}"
