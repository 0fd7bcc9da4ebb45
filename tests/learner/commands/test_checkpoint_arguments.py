"""What ``evaluate`` and ``render`` play when given a run directory: its recorded validated policy, else its
latest checkpoint."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from learner.commands.arguments import UsageError
from learner.commands.checkpoint_arguments import read_checkpoint
from learner.core.checkpoint import checkpoint_path
from learner.core.json_file import write_json
from learner.evaluation.selection import RECORD, Validated, choice_record
from tests.learner.tiny_checkpoint import save_untrained_checkpoint


def test_a_run_directory_reads_as_its_validated_policy_where_one_is_recorded(tmp_path: Path) -> None:
    first = save_untrained_checkpoint(tmp_path)
    later = shutil.copy(first, checkpoint_path(tmp_path, 1024))
    assert read_checkpoint(tmp_path).path == later
    candidates = [Validated(first, 512, 0.9), Validated(Path(later), 1024, 0.5)]
    write_json(tmp_path / RECORD, choice_record(tmp_path, candidates, candidates[0], 200, 200_000, 512, 512))
    assert read_checkpoint(tmp_path).path == first
    assert read_checkpoint(Path(later)).path == Path(later)  # a file is read as given


@pytest.mark.parametrize("damage", ["not json", "no choice", "checkpoint gone"])
def test_a_record_that_cannot_say_what_it_chose_is_a_usage_error_naming_it(tmp_path: Path, damage: str) -> None:
    """Playing the latest checkpoint in its place would score a policy the user did not ask for."""
    first = save_untrained_checkpoint(tmp_path)
    later = Path(shutil.copy(first, checkpoint_path(tmp_path, 1024)))
    candidates = [Validated(first, 512, 0.9), Validated(later, 1024, 0.5)]
    record = choice_record(tmp_path, candidates, candidates[0], 200, 200_000, 512, 512)
    if damage == "not json":
        (tmp_path / RECORD).write_text('{"candidates": [', encoding="utf-8")
    else:
        write_json(tmp_path / RECORD, {**record, "chosen": "elsewhere.pt"} if damage == "no choice" else record)
    if damage == "checkpoint gone":
        first.unlink()
    with pytest.raises(UsageError, match=f"{RECORD}.*delete it and the run's policy is chosen again"):
        read_checkpoint(tmp_path)
