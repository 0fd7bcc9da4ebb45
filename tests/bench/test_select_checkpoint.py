"""``bench/select_checkpoint.py``: a finished run's validated policy, chosen on validation episodes and scored
on the screening ones, written where ``bench/screen_report.py`` reads it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from bench.screen_report import read_run
from bench.select_checkpoint import main
from learner.core.checkpoint import checkpoint_path
from tests.learner.tiny_checkpoint import save_untrained_checkpoint


def test_a_runs_validated_policy_is_chosen_and_scored(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "runs" / "tiny-seed0"
    first = save_untrained_checkpoint(run)
    for steps in (1024, 2048, 3072):
        shutil.copy(first, checkpoint_path(run, steps))
    out = tmp_path / "validated"
    arguments = [str(run), "--out", str(out), "--first-step", "1000", "--every", "1000", "--processes", "1"]
    arguments += ["--validation-episodes", "2", "--screening-episodes", "2"]
    main(arguments)

    summary = json.loads((out / "tiny-seed0" / "validation.json").read_text())
    # The first checkpoint at or after 1,000 and 2,000 steps, and the last; one policy, so every candidate
    # validates alike and the tie goes to the latest.
    assert [c["steps"] for c in summary["candidates"]] == [1024, 2048, 3072]
    assert len({c["validation_success"] for c in summary["candidates"]}) == 1
    assert summary["chosen"] == "checkpoints/step_0000003072.pt" and summary["rule"]["validation_seed"] == 200_000
    screening = read_run(out / "tiny-seed0" / "evaluation-hardest.json.xz")
    assert (screening.episodes, screening.first_seed) == (2, 20_000)
    assert screening.score == summary["screening"]["success_rate"]["estimate"]

    main(arguments)
    assert "tiny-seed0: done before, skipped" in capsys.readouterr().out
