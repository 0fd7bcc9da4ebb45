"""SQLite persistence for curricula, issued tasks and accepted results.

Every write is committed before the request that made it is answered. Writes are group-committed
on the event loop: whatever the loop queued while handling one round of ready requests goes into
one transaction, committed right after that round, so a disk sync is shared by every request in
it. (A writer thread was measured and rejected: each SQLite call hands the GIL back and forth with
a busy event loop, and the waits swamp the commits.) Writes complete, and their ``on_commit``
callbacks run, in the order they were submitted: the teachers see results in exactly the order
they are stored, which is the order a replay feeds them back.
"""

from __future__ import annotations

import asyncio
import json
import logging
import sqlite3
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from common.task_space import Task

log = logging.getLogger(__name__)

SCHEMA_VERSION = 1
_SCHEMA = """
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

INSERT_CURRICULUM = "INSERT INTO curricula (id, name, spec, created_at) VALUES (?, ?, ?, ?)"
INSERT_TASK = "INSERT INTO tasks (curriculum_id, task_index, params, results_seen, issued_at) VALUES (?, ?, ?, ?, ?)"
INSERT_RESULT = (
    "INSERT INTO results (curriculum_id, task_index, reward, success, length, received_at) VALUES (?, ?, ?, ?, ?, ?)"
)
INSERT_FIT = (  # REPLACE: a replay may record again a fit whose live row was written out of order
    "INSERT OR REPLACE INTO fits"
    " (curriculum_id, fit_index, tasks_sampled, results_seen, started_at, finished_at, error)"
    " VALUES (?, ?, ?, ?, ?, ?, ?)"
)

Statements = list[tuple[str, list[tuple[Any, ...]]]]
"""SQL statements, each with the rows to run it on (``executemany``)."""


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
    task_index: int
    task: Task
    reward: float
    success: bool | None
    length: int | None
    received_at: float


@dataclass(frozen=True)
class StoredFit:
    index: int
    tasks_sampled: int
    """Tasks the teacher had drawn when the fit was installed."""
    results_seen: int
    started_at: float
    finished_at: float
    error: str | None


@dataclass
class _Write:
    statements: Statements
    future: asyncio.Future[None] | None
    on_commit: Callable[[], object] | None
    on_abort: Callable[[], object] | None
    error: BaseException | None = field(default=None)


class Store:
    """The service's database. Reads and ``write_now`` are for startup; once ``start`` has run,
    every write goes through ``write`` or ``write_later``, on the event loop thread."""

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

    def _migrate(self) -> None:
        version = self._db.execute("PRAGMA user_version").fetchone()[0]
        if version == SCHEMA_VERSION:
            return
        if version != 0:
            raise StoreError(f"{self.path}: schema version {version}, this service reads version {SCHEMA_VERSION}")
        self._db.executescript(f"BEGIN; {_SCHEMA} PRAGMA user_version = {SCHEMA_VERSION}; COMMIT;")

    def curricula(self) -> list[StoredCurriculum]:
        rows = self._db.execute("SELECT id, name, spec, created_at FROM curricula ORDER BY id")
        return [StoredCurriculum(*row) for row in rows]

    def tasks(self, curriculum_id: int) -> list[StoredTask]:
        rows = self._db.execute(
            "SELECT task_index, results_seen FROM tasks WHERE curriculum_id = ? ORDER BY task_index", (curriculum_id,)
        )
        return [StoredTask(*row) for row in rows]

    def result_count(self, curriculum_id: int) -> int:
        row = self._db.execute("SELECT count(*) FROM results WHERE curriculum_id = ?", (curriculum_id,)).fetchone()
        count: int = row[0]
        return count

    def results(self, curriculum_id: int) -> Iterator[StoredResult]:
        """Accepted results in the order the teacher learned from them, with the tasks they answer."""
        rows = self._db.execute(
            "SELECT r.task_index, t.params, r.reward, r.success, r.length, r.received_at"
            " FROM results r JOIN tasks t USING (curriculum_id, task_index)"
            " WHERE r.curriculum_id = ? ORDER BY r.seq",
            (curriculum_id,),
        )
        for index, params, reward, success, length, received_at in rows:
            yield StoredResult(
                index, json.loads(params), reward, None if success is None else bool(success), length, received_at
            )

    def outstanding_tasks(self, curriculum_id: int, first_index: int) -> Iterator[tuple[int, Task, float]]:
        """Issued tasks from ``first_index`` on that have no result yet, with when they were issued."""
        rows = self._db.execute(
            "SELECT t.task_index, t.params, t.issued_at FROM tasks t"
            " WHERE t.curriculum_id = ? AND t.task_index >= ? AND NOT EXISTS"
            " (SELECT 1 FROM results r WHERE r.curriculum_id = t.curriculum_id AND r.task_index = t.task_index)"
            " ORDER BY t.task_index",
            (curriculum_id, max(first_index, 0)),
        )
        for index, params, issued_at in rows:
            yield index, json.loads(params), issued_at

    def answered_tasks(self, curriculum_id: int, indices: list[int]) -> set[int]:
        """Which of these tasks have a stored result (at most ``MAX_RESULTS_PER_REQUEST`` of them)."""
        marks = ", ".join("?" * len(indices))  # placeholders only: the values stay bound parameters
        rows = self._db.execute(
            f"SELECT task_index FROM results WHERE curriculum_id = ? AND task_index IN ({marks})",
            (curriculum_id, *indices),
        )
        return {index for (index,) in rows}

    def fits(self, curriculum_id: int) -> list[StoredFit]:
        rows = self._db.execute(
            "SELECT fit_index, tasks_sampled, results_seen, started_at, finished_at, error"
            " FROM fits WHERE curriculum_id = ? ORDER BY fit_index",
            (curriculum_id,),
        )
        return [StoredFit(*row) for row in rows]

    def write_now(self, statements: Statements) -> None:
        """Commit on the spot; only before ``start``, when there is no event loop to group on."""
        if self._loop is not None:
            raise RuntimeError("Store.write_now after Store.start: use write")
        self._db.execute("BEGIN IMMEDIATE")
        try:
            for sql, rows in statements:
                self._db.executemany(sql, rows)
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """From now on, writes are grouped and committed on ``loop``."""
        self._loop = loop

    def write(
        self,
        statements: Statements,
        on_commit: Callable[[], object] | None = None,
        on_abort: Callable[[], object] | None = None,
    ) -> asyncio.Future[None]:
        """Queue statements for one atomic write; call from the event loop.

        The future resolves once they are committed, after ``on_commit`` ran, or fails with
        ``StoreError`` after ``on_abort`` ran. The callbacks run even when the caller stopped
        awaiting, so bookkeeping never depends on the request surviving; what they return is ignored.
        """
        if self._loop is None:
            raise RuntimeError("Store.write before Store.start")
        future: asyncio.Future[None] = self._loop.create_future()
        self._queue(_Write(statements, future, on_commit, on_abort))
        return future

    def write_later(self, statements: Statements) -> None:
        """Queue a write nobody waits for (telemetry); a failure is logged."""
        self._queue(_Write(statements, None, None, None))

    def close(self) -> None:
        """Commit what is queued, then close the database."""
        self._flush()
        self._db.close()

    def _queue(self, write: _Write) -> None:
        assert self._loop is not None
        if not self._pending:
            self._loop.call_soon(self._flush)
        self._pending.append(write)

    def _flush(self) -> None:
        group, self._pending = self._pending, []
        if group:
            try:
                self._commit(group)
            finally:
                self._complete(group)

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
                self._db.execute("RELEASE one_write")
            self._db.execute("COMMIT")
        except BaseException as error:
            log.exception("commit of %d writes failed", len(group))
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

    @staticmethod
    def _complete(group: list[_Write]) -> None:
        for write in group:
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
