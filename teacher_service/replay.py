"""Start-up replay: rebuild one curriculum's teacher and bookkeeping from the store.

What is stored lets a restart rebuild the exact live state in bounded time. Each task row carries
how many results the teacher had learned from when it was drawn, and each fit row how many tasks
and results it had seen when it was installed, and the fitted model; every ``snapshot_every``
results the curriculum stores a snapshot (see ``curricula``). A restart restores the newest
snapshot, then replays only the results stored after it, in order, drawing (and dropping) tasks
and installing fits from their stored models at the same points; so the rebuilt teacher has the
same model, counters and per-task bookkeeping, and draws the same next tasks, and no installed fit
is ever run again. A fit that was due but never recorded (the process died first) runs again
once, through the fit process, as it would have live. The first start on a database without
snapshots (schema version 1) replays everything and runs the fits whose models were never stored;
the curriculum then stores a snapshot, as after every start that replayed anything.

A snapshot stored by another version may not restore into today's teacher (its kind's state
format changed). ``replay`` then raises ``SnapshotUnusable`` and the caller rebuilds the
curriculum with ``from_start``: a fresh teacher learns every stored result again, from the first,
as the schema-1 start does. A stored fit model that today's teacher cannot read is treated like
one never stored: the fit runs again at the point it was installed, and its new model replaces
the stored one; fits that failed live stay failed. The snapshot stored after that rebuild holds
the whole history, and replaces the old history rows.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from tqdm import tqdm

from teacher_service.fits import FitOutcome, run_fit
from teacher_service.store import AwaitedTask, Store, StoredFit, StoredResult, StoredTask
from teacher_service.teachers import EpisodeResult, FitJob, Teacher

log = logging.getLogger(__name__)


class SnapshotUnusable(Exception):
    """The stored snapshot cannot restore today's teacher; replay the curriculum ``from_start``."""


@dataclass(frozen=True)
class Replayed:
    """What a restart rebuilt for one curriculum besides its teacher, which it rebuilt in place."""

    tasks_issued: int
    """Tasks handed out (stored) before the restart."""
    issued_index_end: int
    """One past the highest stored task index; the rebuilt teacher has drawn this many tasks."""
    results_replayed: int
    """Results stored after the snapshot, learned again here."""
    last_result_index: int | None
    """Task answered by the last replayed result; ``None`` when none was replayed."""
    snapshot_at: int
    """Results learned at the stored snapshot (0 without one)."""
    history_stored: int
    """History rows stored with that snapshot."""
    awaited: list[tuple[AwaitedTask, int]]
    """Tasks inside the task window still awaiting a result, oldest first, each with its ordinal
    among the stored tasks (the window counts stored tasks, not indices)."""
    lost_fits: list[FitJob]
    """Fits that fell due and were never recorded: they run once the service has started."""
    rerun_fits: list[StoredFit]
    """Fits stored without a model (by a version-1 service), or with one this version cannot read,
    and run again here, with their models (or errors) now; they are to be stored again."""
    recent_fits: list[StoredFit]
    """The last fits for the API's fit history, oldest first, with the errors of the fits run again."""
    fits_completed: int
    recent_results: list[StoredResult]
    """The last results for the API, oldest first."""


def replay(
    store: Store,
    curriculum_id: int,
    name: str,
    teacher: Teacher,
    *,
    task_window: int,
    fit_history: int,
    recent_results: int,
    from_start: bool = False,
) -> Replayed:
    """Rebuild ``teacher`` (fresh, as ``make_teacher`` built it) from the curriculum's newest
    snapshot and the results stored after it, or from every stored result with ``from_start``
    (see the module docstring); before the service starts. Raises ``SnapshotUnusable`` when the
    snapshot does not restore; ``teacher`` is then spoilt."""
    stored = None if from_start else store.snapshot(curriculum_id)
    after_seq = tasks_issued = issued_index_end = history_stored = 0
    waiting: list[int] = []
    awaited_then: list[int] = []
    if stored is not None:
        try:
            kept_from = teacher.history_kept_from(stored.teacher)
            teacher.restore(stored.teacher, store.history(curriculum_id, stored.history_rows, kept_from))
        except Exception as error:
            raise SnapshotUnusable(f"{type(error).__name__}: {error}") from error
        after_seq, tasks_issued, issued_index_end = stored.last_seq, stored.tasks_issued, stored.issued_index_end
        waiting, history_stored = stored.fits_waiting, stored.history_rows
        teacher.release_history(history_stored)
        awaited_then = stored.outstanding
    later_tasks = store.tasks_from(curriculum_id, issued_index_end)
    snapshot_at = teacher.results_seen
    recorded = {fit.index: fit for fit in store.fits_since(curriculum_id, teacher.results_seen)}
    due = deque(teacher.refit_job(index) for index in waiting)
    drawn_before = _tasks_drawn_before(later_tasks)
    rerun_fits: list[StoredFit] = []
    answered: set[int] = set()
    last_result_index: int | None = None

    def draw_to(count: int) -> None:
        if count > teacher.tasks_drawn:
            teacher.skip(count - teacher.tasks_drawn)

    def install_recorded(results_applied: int) -> None:
        while due and (fit := recorded.get(due[0].index)) and fit.results_seen <= results_applied:
            draw_to(fit.tasks_drawn)
            _install_stored(name, teacher, due.popleft(), fit, rerun_fits)

    total = store.result_count(curriculum_id, after_seq)
    results = store.results(curriculum_id, after_seq)
    for result in tqdm(results, total=total, desc=f"replaying {name}", unit="result", disable=None, leave=False):
        install_recorded(teacher.results_seen)
        draw_to(drawn_before(teacher.results_seen))
        job = teacher.learn(EpisodeResult(result.task, result.reward, result.success, result.length, result.score))
        last_result_index = result.task_index
        answered.add(result.task_index)
        if job is not None:
            due.append(job)
    install_recorded(teacher.results_seen)
    issued_end_now = later_tasks[-1].index + 1 if later_tasks else issued_index_end
    draw_to(issued_end_now)
    tasks_issued_now = tasks_issued + len(later_tasks)
    in_window = store.last_task_indices(curriculum_id, task_window)
    ordinals = {index: tasks_issued_now - len(in_window) + rank for rank, index in enumerate(in_window)}
    oldest_kept = in_window[0] if in_window else issued_end_now
    recent_then = [index for index in awaited_then if index >= oldest_kept]
    awaited = [
        (task, ordinals[task.index])
        for task in store.awaited_tasks(curriculum_id, recent_then, max(issued_index_end, oldest_kept))
        if task.index not in answered
    ]
    errors = {fit.index: fit.error for fit in rerun_fits}
    return Replayed(
        tasks_issued=tasks_issued_now,
        issued_index_end=issued_end_now,
        results_replayed=total,
        last_result_index=last_result_index,
        snapshot_at=snapshot_at,
        history_stored=history_stored,
        awaited=awaited,
        lost_fits=list(due),
        rerun_fits=rerun_fits,
        recent_fits=[
            dataclasses.replace(fit, error=errors.get(fit.index, fit.error))
            for fit in store.recent_fits(curriculum_id, fit_history)
        ],
        fits_completed=store.fit_count(curriculum_id),
        recent_results=store.recent_results(curriculum_id, recent_results),
    )


def _install_stored(name: str, teacher: Teacher, job: FitJob, fit: StoredFit, rerun_fits: list[StoredFit]) -> None:
    """Install a recorded fit from its stored model; one stored without a model (by a version-1
    service), or with one today's teacher cannot read, runs again here, and joins ``rerun_fits``
    with its model, to be stored for next time."""
    if fit.error is not None:
        return
    try:
        if fit.model is not None:
            try:
                fitted = teacher.import_fit(json.loads(fit.model))
            except Exception as unreadable:
                log.warning(
                    "curriculum %r: stored fit %d's model does not load in this version (%s: %s); running it again",
                    name,
                    fit.index,
                    type(unreadable).__name__,
                    unreadable,
                )
            else:
                teacher.install(fitted)
                return
        outcome = _rerun(job, fit)
        error = outcome.error
        if error is None:
            teacher.install(outcome.output)
    except Exception as exception:
        log.exception("curriculum %r: installing stored fit %d failed", name, fit.index)
        error = f"install failed: {type(exception).__name__}: {exception}"
    model = None if error is not None else json.dumps(teacher.export_fit(outcome.output))
    rerun_fits.append(dataclasses.replace(fit, error=error, model=model))


def _rerun(job: FitJob, recorded: StoredFit) -> FitOutcome:
    """Run a job again, keeping the live run's timing so the fit history survives restarts.

    A fit that failed live fails again here without running: had it succeeded on replay, the
    rebuilt teacher would sample from a model the live one never had.
    """
    if recorded.error is not None:
        return FitOutcome(job.index, None, recorded.error, recorded.started_at, recorded.finished_at)
    outcome = run_fit(job)
    return FitOutcome(outcome.index, outcome.output, outcome.error, recorded.started_at, recorded.finished_at)


def _tasks_drawn_before(tasks: list[StoredTask]) -> Callable[[int], int]:
    """Maps a count of applied results to how many tasks the live teacher had drawn by then."""
    marks = iter(tasks)
    drawn = 0
    pending = next(marks, None)

    def drawn_before(results_applied: int) -> int:
        nonlocal drawn, pending
        while pending is not None and pending.results_seen <= results_applied:
            drawn = pending.index + 1
            pending = next(marks, None)
        return drawn

    return drawn_before
