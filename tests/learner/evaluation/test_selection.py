"""The validated policy's candidates and its choice (``learner.evaluation.selection``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from learner.core.checkpoint import checkpoint_path, checkpoint_steps
from learner.core.json_file import write_json
from learner.evaluation.selection import (
    RECORD,
    Validated,
    candidate_checkpoints,
    choice_record,
    choose,
    recorded_choice,
    schedule,
)

PERIOD = 81_920
"""A hard-family run's checkpoint period (20 iterations of 4,096 steps)."""


def run_with_checkpoints(run_dir: Path, steps: list[int]) -> Path:
    for each in steps:
        path = checkpoint_path(run_dir, each)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.touch()
    return run_dir


def test_a_six_million_step_run_has_seven_candidates_the_last_its_final_checkpoint(tmp_path: Path) -> None:
    # Periodic checkpoints, one written where a SIGINT stopped the run, and the final one past the budget.
    periodic = [PERIOD * k for k in range(1, 74)]
    run = run_with_checkpoints(tmp_path, [*periodic, 1_978_368, 6_000_640])
    assert schedule(6_000_000) == (3_000_000, 500_000)
    steps = [checkpoint_steps(path) for path in candidate_checkpoints(run, *schedule(6_000_000))]
    # The first at or after 3.0, 3.5, 4.0, 4.5, 5.0 and 5.5M; the one after 6.0M is the final one.
    assert steps == [3_031_040, 3_522_560, 4_014_080, 4_505_600, 5_079_040, 5_570_560, 6_000_640]


def test_a_run_shorter_than_the_first_step_has_only_its_last_checkpoint(tmp_path: Path) -> None:
    run = run_with_checkpoints(tmp_path, [PERIOD, 2 * PERIOD])
    assert candidate_checkpoints(run, *schedule(6_000_000)) == [checkpoint_path(run, 2 * PERIOD)]


def test_no_checkpoints_or_bad_spacing_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no checkpoints"):
        candidate_checkpoints(tmp_path, 0, 1)
    with pytest.raises(ValueError, match="every at least 1"):
        candidate_checkpoints(tmp_path, 0, every=0)
    with pytest.raises(ValueError, match="not a checkpoint file"):
        checkpoint_steps(tmp_path / "final.pt")


def test_the_best_on_validation_is_chosen_and_a_tie_goes_to_the_later() -> None:
    early, middle, final = (Validated(Path(f"step_{s}.pt"), s, rate) for s, rate in [(3, 0.9), (4, 0.95), (6, 0.95)])
    assert choose([early, middle, final]) == final
    assert choose([early, final.__class__(final.path, final.steps, 0.5)]) == early
    with pytest.raises(ValueError):
        choose([])


def test_a_recorded_choice_holds_until_the_run_trains_on(tmp_path: Path) -> None:
    run = run_with_checkpoints(tmp_path, [PERIOD, 2 * PERIOD, 3 * PERIOD])
    validated = [Validated(path, checkpoint_steps(path), 0.5) for path in candidate_checkpoints(run, PERIOD, PERIOD)]
    best = Validated(validated[0].path, validated[0].steps, 0.9)
    write_json(run / RECORD, choice_record(run, [best, *validated[1:]], best, 200, 200_000, PERIOD, PERIOD))
    assert recorded_choice(run) == Validated(checkpoint_path(run, PERIOD), PERIOD, 0.9)
    # A resumed run's later checkpoint leaves the record stale: the run is read as its final policy again.
    run_with_checkpoints(run, [4 * PERIOD])
    assert recorded_choice(run) is None
    assert recorded_choice(tmp_path / "no-run") is None
