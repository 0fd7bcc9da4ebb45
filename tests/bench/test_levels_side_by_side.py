"""The level side-by-side's runs on its shared service: a run made again never inherits the curriculum of
the run it replaces (a rerun once replayed the old run's results into its new teacher)."""

from __future__ import annotations

import shutil
from pathlib import Path

from bench.levels_side_by_side import curriculum_name


def test_a_run_made_again_gets_a_curriculum_of_its_own(tmp_path: Path) -> None:
    run_dir = tmp_path / "plr-seed0"
    run_dir.mkdir()
    first = curriculum_name(run_dir, "doorkey-plr-seed0", resuming=False)
    assert first.startswith("doorkey-plr-seed0-")
    assert curriculum_name(run_dir, "doorkey-plr-seed0", resuming=True) == first, "a resume keeps its curriculum"
    shutil.rmtree(run_dir)
    run_dir.mkdir()
    assert curriculum_name(run_dir, "doorkey-plr-seed0", resuming=False) != first


def test_a_run_resumed_from_before_the_suffix_keeps_its_name(tmp_path: Path) -> None:
    assert curriculum_name(tmp_path, "doorkey-plr-seed0", resuming=True) == "doorkey-plr-seed0"


def test_names_stay_within_the_services_limit(tmp_path: Path) -> None:
    assert len(curriculum_name(tmp_path, "x" * 80, resuming=False)) <= 64
