"""``bench/screen_report.py``: a screen's arms read from their evaluation files, tested and summarised."""

from __future__ import annotations

import json
import lzma
from pathlib import Path

import pytest

from bench.screen_report import ScreenError, main, read_arms


def write_evaluation(path: Path, score: float, episodes: int = 500, seed: int = 20000) -> Path:
    """An evaluation file as ``kuka-curriculum evaluate`` writes it (the fields the report reads), xz or plain."""
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps({"success_rate": {"estimate": score}, "episodes": episodes, "seed": seed})
    if path.suffix == ".xz":
        path.write_bytes(lzma.compress(text.encode()))
    else:
        path.write_text(text)
    return path


def test_a_screen_is_reported_from_its_files(tmp_path: Path) -> None:
    for index, score in enumerate([0.9, 0.85, 0.81]):
        write_evaluation(tmp_path / "lever" / f"seed{index}" / "evaluation-hardest.json.xz", score)
    for index, score in enumerate([0.2, 0.5, 0.79]):
        write_evaluation(tmp_path / "baseline" / f"run{index}.json", score)
    out = tmp_path / "report"
    main(
        [
            *("--out", str(out), "--baseline", "baseline", "--reps", "100"),
            *("--arm", f"baseline={tmp_path}/baseline/*.json", "--arm", f"lever={tmp_path}/lever/*/*.json.xz"),
        ]
    )
    report = json.loads((out / "results.json").read_text())
    assert report["episodes"] == 500 and report["first_episode_seed"] == 20000
    # 0.79 is under the 80% bar: 0 good in the baseline, 3 in the lever's arm.
    assert report["tests"]["lever"] == {"good_runs": 3, "runs": 3, "fisher_one_sided_p": pytest.approx(0.05)}
    lever = report["run_statistics"]["arms"]["lever"]
    assert lever["scores"] == [0.9, 0.85, 0.81] and lever["improvement_over_baseline"]["estimate"] == 1.0
    assert "| lever | 3 of 3 | p = 0.050 |" in (out / "results.md").read_text()
    assert (out / "performance_profile.png").stat().st_size > 0


def test_runs_on_other_episodes_are_refused(tmp_path: Path) -> None:
    write_evaluation(tmp_path / "a.json", 0.9)
    write_evaluation(tmp_path / "b.json", 0.9, seed=100000)
    with pytest.raises(ScreenError, match="different episodes"):
        read_arms({"a": [str(tmp_path / "a.json")], "b": [str(tmp_path / "b.json")]})


def test_an_arm_with_no_file_or_an_unreadable_one_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "broken.json").write_text("{")
    for pattern in (f"{tmp_path}/missing/*.json", f"{tmp_path}/broken.json"):
        with pytest.raises(SystemExit) as exit_info:
            main(["--out", str(tmp_path / "out"), "--baseline", "a", "--arm", f"a={pattern}"])
        assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert "no file matches" in error and "not an evaluation file" in error
