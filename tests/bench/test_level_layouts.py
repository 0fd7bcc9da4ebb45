"""The layout count: DoorKey-5x5's held-out seeds replay its training grids, the gamut's held-out levels are
layouts of their own, and the table prints what the counts say."""

from __future__ import annotations

import pytest

from bench.level_layouts import count_layouts, main


def test_doorkey_s_held_out_grids_are_training_grids_and_the_gamut_s_are_not() -> None:
    doorkey = count_layouts("MiniGrid-DoorKey-5x5-v0", 40, 10)
    assert doorkey["training_grids"] <= 6 and doorkey["held_out_grids_in_training"] == 10
    gamut = count_layouts("MiniGrid-Gamut-v0", 40, 10)
    assert gamut["training_layouts"] == 40 and gamut["held_out_layouts"] == 10
    assert gamut["held_out_layouts_in_training"] == 0 and gamut["held_out_grids_in_training"] == 0


def test_the_table_has_a_row_per_family(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--env", "MiniGrid-Gamut-v0", "--levels", "16", "--held-out", "4"]) == 0
    assert "| MiniGrid-Gamut-v0 | 16 | 16 (16) | 4 | 4 (4) | 0 (0) |" in capsys.readouterr().out
