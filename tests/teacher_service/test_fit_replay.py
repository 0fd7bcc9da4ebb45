"""Replaying a curriculum redoes its fits, except those that failed live: they stay failed."""

from __future__ import annotations

from teacher_service.replay import _rerun
from teacher_service.store import StoredFit
from teacher_service.teachers import FitJob


def _never_run() -> None:
    raise AssertionError("a fit that failed live must not run on replay")


def test_a_fit_that_failed_live_fails_again_on_replay_without_running() -> None:
    recorded = StoredFit(
        index=3,
        tasks_drawn=40,
        results_seen=32,
        started_at=10.0,
        finished_at=11.5,
        error="MemoryError: fit process ran out of memory",
    )
    outcome = _rerun(FitJob(index=3, run=_never_run), recorded)
    assert (outcome.index, outcome.output, outcome.error) == (3, None, recorded.error)
    assert (outcome.started_at, outcome.finished_at) == (10.0, 11.5)


def test_a_fit_that_succeeded_live_runs_again_with_its_live_timing() -> None:
    recorded = StoredFit(index=0, tasks_drawn=16, results_seen=16, started_at=1.0, finished_at=2.0, error=None)
    outcome = _rerun(FitJob(index=0, run=lambda: "model"), recorded)
    assert (outcome.output, outcome.error, outcome.started_at, outcome.finished_at) == ("model", None, 1.0, 2.0)
