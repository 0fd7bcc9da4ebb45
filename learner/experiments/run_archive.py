"""A finished run packed for keeping: what the write-up reads, for git; what a resume needs, on disk only.

A run directory straight out of ``kuka-curriculum train`` holds its teacher's SQLite database, the
metrics log, the training and teacher logs, TensorBoard events and a checkpoint every few iterations.
The write-up reads three of them: the metrics (learning curves), the final evaluation and the final
checkpoint (so a reader can evaluate it again). Once a bake-off run or a tune trial is trained (and
evaluated), ``archive_run`` leaves the run in this form:

- for git (``write_up_files``): ``evaluation.json.xz`` (a bake-off's runs), ``metrics.jsonl.xz`` with
  the fields the write-ups read alone (``WRITE_UP_METRICS``, ``thin_metrics``) and ``checkpoints/``
  with the final checkpoint alone, evaluation-only (``save_evaluation_only``: no optimiser state, a
  third of the size; evaluate and render read it), the earlier ones deleted; a run trained with
  ``--policy-choice validated`` also keeps its chosen checkpoint, evaluation-only, and ``validated-policy.json``;
- on disk only (``resume_files``, git-ignored): ``resume.pt``, the final checkpoint in full,
  ``metrics.full.jsonl.xz``, the metrics log in full, and ``teacher.sqlite.xz``, ``train.log.xz`` and
  ``teacher.log.xz``, which ``restore_run`` puts back before a larger budget resumes the run (the full
  metrics as the raw ``metrics.jsonl``, which training appends to), and ``tensorboard/``.

Readers go through ``read_text``, which takes either form, so directories written before archiving
existed (the committed v1 bake-offs) read as they are; so does a run archived before its metrics were
split (its ``metrics.jsonl.xz`` the full log, with no full copy beside it), and ``restore_run`` restores
it as before. The measured sizes: docs/results/bakeoff-hard.md.

Each step is safe to interrupt: a compressed file is written under a temporary name and renamed,
and the raw file goes only after that, so a raw file present is always the authoritative copy.
"""

from __future__ import annotations

import contextlib
import fnmatch
import json
import lzma
import os
import shutil
import sqlite3
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from learner.core.checkpoint import (
    CHECKPOINT_DIR,
    checkpoint_path,
    latest_checkpoint,
    load_checkpoint,
    save_evaluation_only,
)
from learner.core.metrics import METRICS_FILE
from learner.evaluation.selection import RECORD as VALIDATION_RECORD
from learner.evaluation.selection import run_policy

SUFFIX = ".xz"
TRAIN_LOG = "train.log"
EVALUATION_FILE = "evaluation.json"
"""A bake-off run's final evaluation (``bakeoff_runs``), kept for git xz-compressed like the metrics (the
sizes: docs/results/bakeoff-hard.md)."""
RESUME_CHECKPOINT = "resume.pt"
"""The final checkpoint in full, optimiser state included, for resuming: on disk only, while git keeps its
evaluation-only copy in ``checkpoints/``."""
TENSORBOARD_DIR = "tensorboard"
"""The run's TensorBoard events, which duplicate its metrics log: left on disk, never for git."""
FULL_METRICS = "metrics.full.jsonl"
"""An archived run's metrics log in full (compressed, on disk only), while git keeps ``WRITE_UP_METRICS``."""
WRITE_UP_METRICS = (
    "step",
    "time",
    "eval/*",
    "train/episodes",
    "train/success_rate",
    "perf/steps_per_second",
)
"""The fields (patterns) an archived run's git copy of its metrics keeps, those its readers use: step, time, eval/*
(bakeoff_runs, tune_report, curriculum_diagnostics), perf/steps_per_second (bench/levels_side_by_side.py),
train/episodes and train/success_rate (the training success in docs/results/tune.md)."""


def _raw_files() -> tuple[str, ...]:
    """What a run keeps compressed: its teacher database, metrics and logs (xz packs a database to about
    a quarter).

    Imported here, not at the top: the bake-off imports this module, and with the teacher service's
    client loaded up front a Ctrl-C during its final evaluation no longer stopped it (the
    Ctrl-C test in tests/learner/test_bakeoff.py hung).
    """
    from learner.job.teacher_process import DATABASE_FILE, LOG_FILE

    return DATABASE_FILE, METRICS_FILE, TRAIN_LOG, LOG_FILE


def write_up_files() -> tuple[str, ...]:
    """The paths, relative to the run directory, that an archived run keeps for the write-up and git:
    the final evaluation and the metrics, compressed, the checkpoints directory (holding the final one and a
    validated run's chosen one, evaluation-only) and a validated run's record of its choice."""
    return EVALUATION_FILE + SUFFIX, METRICS_FILE + SUFFIX, CHECKPOINT_DIR, VALIDATION_RECORD


def resume_files() -> tuple[str, ...]:
    """The paths, relative to the run directory, that an archived run keeps on disk only (git-ignored):
    what ``restore_run`` needs to resume it (the full final checkpoint and metrics log, the compressed
    teacher database and logs) and TensorBoard's events."""
    database, _metrics, *logs = _raw_files()
    return (
        RESUME_CHECKPOINT,
        FULL_METRICS + SUFFIX,
        database + SUFFIX,
        *(log + SUFFIX for log in logs),
        TENSORBOARD_DIR,
    )


def compressed(path: Path) -> Path:
    return path.with_name(path.name + SUFFIX)


def read_text(path: Path) -> str | None:
    """The file's text from its raw form, else from its compressed one; None when neither exists."""
    if path.exists():
        return path.read_text(encoding="utf-8", errors="replace")
    packed = compressed(path)
    if packed.exists():
        return lzma.decompress(packed.read_bytes()).decode("utf-8", errors="replace")
    return None


def read_json(path: Path) -> Any:
    """A JSON file, named by its raw name (read raw, else compressed, as ``read_text``) or by its compressed
    one (``evaluation.json.xz``); ``FileNotFoundError`` when neither form is there."""
    path = Path(path)
    if path.name.endswith(SUFFIX) and path.exists():
        return json.loads(_decompressed(path))
    text = read_text(path)
    if text is None:
        raise FileNotFoundError(f"{path} is not there, raw or compressed")
    return json.loads(text)


def metrics_records(run_dir: Path) -> list[dict[str, Any]]:
    """The run's metric records, from either form of its metrics log; a line cut short (a crash mid-write,
    or the training process writing now) is left out."""
    records = []
    for line in (read_text(Path(run_dir) / METRICS_FILE) or "").splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


def exists(path: Path) -> bool:
    """Whether the file is there, raw or compressed."""
    return path.exists() or compressed(path).exists()


@contextlib.contextmanager
def unpacked(path: Path) -> Iterator[Path]:
    """The file itself when raw; else its compressed form decompressed into a temporary file, removed
    afterwards (a database has to be a plain file for SQLite to open it)."""
    if path.exists():
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="run-archive-") as scratch:
        copy = Path(scratch) / path.name
        with lzma.open(compressed(path), "rb") as source, copy.open("wb") as target:
            shutil.copyfileobj(source, target)
        yield copy


def _close_database(path: Path) -> None:
    """Fold a leftover write-ahead log into the database, so the one file compressed is complete."""
    if path.exists():
        connection = sqlite3.connect(path)
        try:
            connection.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        finally:
            connection.close()
    for leftover in ("-wal", "-shm"):
        path.with_name(path.name + leftover).unlink(missing_ok=True)


def _compress(source: Path, target: Path) -> None:
    """``source`` xz-compressed to ``target``, written whole under a temporary name first."""
    partial = target.with_name(target.name + ".partial")
    with source.open("rb") as raw, lzma.open(partial, "wb", preset=6) as packed:
        shutil.copyfileobj(raw, packed)
    os.replace(partial, target)


def _decompress(source: Path, target: Path) -> None:
    """``source`` decompressed to ``target``, written whole under a temporary name first."""
    partial = target.with_name(target.name + ".partial")
    with lzma.open(source, "rb") as packed, partial.open("wb") as raw:
        shutil.copyfileobj(packed, raw)
    os.replace(partial, target)


def _pack(path: Path) -> None:
    _compress(path, compressed(path))
    path.unlink()


def _unpack(path: Path) -> None:
    _decompress(compressed(path), path)
    compressed(path).unlink()


def full_log(log: Path) -> Path:
    """Where ``thin_metrics`` keeps a metrics log in full, compressed: ``FULL_METRICS`` + ``SUFFIX`` beside
    ``metrics.jsonl`` (``metrics-x.full.jsonl.xz`` beside ``metrics-x.jsonl``)."""
    return compressed(log.with_suffix(".full" + log.suffix))


def _kept(field: str) -> bool:
    return any(fnmatch.fnmatchcase(field, pattern) for pattern in WRITE_UP_METRICS)


def _thin(text: str) -> str:
    """Each record of a metrics log with ``WRITE_UP_METRICS`` alone, in their order, values as they were
    (json round-trips them); a line cut short is left out, as ``metrics_records`` leaves it out."""
    lines = []
    for line in text.splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue
        lines.append(json.dumps({field: value for field, value in record.items() if _kept(field)}) + "\n")
    return "".join(lines)


def _decompressed(path: Path) -> str:
    return lzma.decompress(path.read_bytes()).decode("utf-8", errors="replace")


def thin_metrics(log: Path) -> None:
    """Split a metrics log (``run_dir / METRICS_FILE``): in full, compressed, to ``full_log(log)`` (on disk
    only, for resuming), and for git its compressed copy ``metrics.jsonl.xz`` with ``WRITE_UP_METRICS`` alone.

    The full log comes from the raw file when there is one (always the authoritative copy; removed last),
    else from a ``metrics.jsonl.xz`` compressed before this split, which is the full log (copied as it is;
    the fullest copy there is, whatever it holds beyond ``WRITE_UP_METRICS``).
    A log already split, or a git copy already thin with no full log beside it (a clone), is left
    untouched. Safe to interrupt and to call again.
    """
    log = Path(log)
    packed, full = compressed(log), full_log(log)
    if log.exists():
        _compress(log, full)
    elif not full.exists():
        text = _decompressed(packed) if packed.exists() else ""
        if _thin(text) == text:  # nothing to split: no log, or only the git copy, thin already
            return
        partial = full.with_name(full.name + ".partial")
        shutil.copyfile(packed, partial)
        os.replace(partial, full)
    thin = _thin(_decompressed(full))
    if log.exists() or not packed.exists() or _decompressed(packed) != thin:
        partial = packed.with_name(packed.name + ".partial")
        with lzma.open(partial, "wb", preset=6) as target:
            target.write(thin.encode("utf-8"))
        os.replace(partial, packed)
    log.unlink(missing_ok=True)


def archive_run(run_dir: Path) -> None:
    """Compress a finished, evaluated run's raw files and its evaluation, its metrics log split by
    ``thin_metrics``, and keep only its latest checkpoint and the policy it chose (``--policy-choice
    validated``), evaluation-only, with the latest's full form moved to ``RESUME_CHECKPOINT``.

    Call it only when no process has the run open. A run already archived is left untouched (one
    archived before the metrics were split too: ``thin_metrics`` splits it when called on its own).
    """
    run_dir = Path(run_dir)
    database, *others = _raw_files()
    _close_database(run_dir / database)
    for name in (database, *others, EVALUATION_FILE):
        if name == METRICS_FILE and (run_dir / name).exists():
            thin_metrics(run_dir / name)
        elif (run_dir / name).exists():
            _pack(run_dir / name)
    final, chosen = latest_checkpoint(run_dir), run_policy(run_dir)
    for entry in (run_dir / CHECKPOINT_DIR).glob("*"):
        if entry not in (final, chosen) and entry.is_file():
            entry.unlink()
    if chosen is not None and chosen != final and not load_checkpoint(chosen).evaluation_only:
        save_evaluation_only(chosen, chosen)
    if final is not None and not load_checkpoint(final).evaluation_only:
        # The full copy is whole before the final checkpoint is slimmed, so an interruption loses nothing.
        partial = run_dir / (RESUME_CHECKPOINT + ".partial")
        shutil.copyfile(final, partial)
        os.replace(partial, run_dir / RESUME_CHECKPOINT)
        save_evaluation_only(final, final)


def restore_run(run_dir: Path) -> None:
    """Put back an archived run's full final checkpoint and decompress its raw files and evaluation, so
    training can resume it from that checkpoint. A run archived without its full checkpoint (the committed
    ones, in a clone) keeps the evaluation-only one, which training refuses to resume from. The metrics come
    back in full (``full_log``) where the run has them, so a resumed run appends to its complete log; a run
    archived before its metrics were split gets its one ``metrics.jsonl.xz`` back."""
    full = Path(run_dir) / RESUME_CHECKPOINT
    if full.exists():
        os.replace(full, checkpoint_path(run_dir, load_checkpoint(full).counters.steps))
    log = Path(run_dir) / METRICS_FILE
    if full_log(log).exists():
        if not log.exists():
            _decompress(full_log(log), log)
        compressed(log).unlink(missing_ok=True)  # the thin copy, once the raw log is whole
        full_log(log).unlink()
    for name in (*_raw_files(), EVALUATION_FILE):
        path = Path(run_dir) / name
        if path.exists():
            compressed(path).unlink(missing_ok=True)
        elif compressed(path).exists():
            _unpack(path)
