"""``bench/bakeoff_run_statistics.py`` recomputes a bake-off's run statistics from its results file."""

from __future__ import annotations

import json
import sys

import pytest

from bench.bakeoff_run_statistics import main


def test_the_run_statistics_of_a_results_file_are_written_where_asked(tmp_path, monkeypatch, capsys):
    results = tmp_path / "results.json"
    rates = {"random": [0.2, 0.3], "currot": [0.9, 0.1]}
    results.write_text(
        json.dumps({"teachers": [{"teacher": t, "runs": [{"success_rate": r} for r in rs]} for t, rs in rates.items()]})
    )
    out = tmp_path / "out"
    monkeypatch.setattr(sys, "argv", ["bakeoff_run_statistics.py", str(results), "--out", str(out), "--reps", "100"])
    main()
    printed = capsys.readouterr().out
    assert printed.startswith("# Run statistics of the bake-off in ")
    # CURROT's 0.9 beats both of random's runs, its 0.1 neither: 2 of 4 pairs.
    assert "| CURROT (`currot`) | 2 | 50% [10%, 90%] | 50% [10%, 90%] | 50% [" in printed and "| 0.50 [" in printed
    assert json.loads((out / "run_statistics.json").read_text())["reps"] == 100
    assert (out / "performance_profile.png").stat().st_size > 0 and not (tmp_path / "run_statistics.md").exists()


def test_a_resample_count_out_of_bounds_is_refused(tmp_path, monkeypatch, capsys):
    """The bootstrap's cost follows --reps, so it is bounded as the bake-off's own --bootstrap-reps is."""
    for reps in ("99", "100001"):
        monkeypatch.setattr(sys, "argv", ["bakeoff_run_statistics.py", str(tmp_path / "results.json"), "--reps", reps])
        with pytest.raises(SystemExit) as exit_info:
            main()
        assert exit_info.value.code == 2 and "--reps" in capsys.readouterr().err
