"""``bench/placement_bands.py`` pools ``evaluate --json`` files into the bake-off's placement
table: one row per teacher over its files, the scripted controller's deterministic episodes counted once, and files of
other episode seeds refused."""

from __future__ import annotations

import json
import lzma
import sys

import pytest

from bench.placement_bands import main
from common.kuka import HARD_V1_ENV_ID
from common.kuka.diagnostics import EpisodeDiagnostics
from common.kuka.task_space import KUKA_HARD_V1_TASK_SPACE
from common.policy.trajectory import EpisodeStats
from learner.evaluation.checkpoint_evaluation import EvaluationResult

TASK = KUKA_HARD_V1_TASK_SPACE.hardest()


def evaluation(placed: list[tuple[float, bool]], seed: int = 100000) -> dict:
    episodes = tuple(EpisodeStats(TASK, 1.0, success, 800) for _, success in placed)
    diagnostics = tuple(EpisodeDiagnostics(x, 0.0, 0.0, 0.01, 0.0, 1.0) for x, _ in placed)
    return EvaluationResult(TASK, seed, episodes, HARD_V1_ENV_ID, diagnostics).to_dict()


def test_files_pool_per_teacher_beside_the_scripted_controller(tmp_path, monkeypatch, capsys):
    scripted = evaluation([(0.58, True), (0.68, True)])
    files = {
        "seed0.json": {"teacher": "currot", **evaluation([(0.58, True), (0.68, False)]), "scripted": scripted},
        "seed1.json": {"teacher": "currot", **evaluation([(0.58, False), (0.68, False)]), "scripted": scripted},
        "scripted.json": {"controller": "scripted", **scripted},
    }
    for name, data in files.items():
        (tmp_path / name).write_text(json.dumps(data))
    out = tmp_path / "bands.json"
    monkeypatch.setattr(sys, "argv", ["placement_bands", *(str(tmp_path / name) for name in files), "--json", str(out)])
    main()
    printed = capsys.readouterr().out
    assert "| CURROT (2 policies) | 25% (4) | 50% (2) | — | 0% (2) | — | — | 2 of 3 (67%) |" in printed
    assert "| Scripted controller (no learning) | 100% (2) |" in printed
    rows = json.loads(out.read_text())["rows"]
    assert [(row["row"], row["episodes"]) for row in rows] == [
        ("CURROT (2 policies)", 4),
        ("Scripted controller (no learning)", 2),
    ]
    assert rows[0]["failures_beyond_clamp"] == {"beyond": 2, "failures": 3}

    # Another file's episodes were played on other seeds: a row over both would mix placements.
    (tmp_path / "other.json").write_text(json.dumps({"teacher": "currot", **evaluation([(0.58, True)], seed=0)}))
    monkeypatch.setattr(sys, "argv", ["placement_bands", str(tmp_path / "seed0.json"), str(tmp_path / "other.json")])
    with pytest.raises(SystemExit, match="played other episodes"):
        main()


def test_a_bake_off_run_evaluation_takes_its_teacher_from_its_directory(tmp_path, monkeypatch, capsys):
    run = tmp_path / "runs" / "self-paced-seed3"
    run.mkdir(parents=True)
    # As a committed bake-off run keeps it: compressed.
    packed = lzma.compress(json.dumps(evaluation([(0.58, True), (0.68, False)])).encode())
    (run / "evaluation.json.xz").write_bytes(packed)
    monkeypatch.setattr(sys, "argv", ["placement_bands", str(run / "evaluation.json.xz")])
    main()
    assert "| Self-paced (SPDL) (1 policy) | 50% (2) |" in capsys.readouterr().out

    # Neither a teacher key nor a run directory: say so rather than guess.
    (tmp_path / "loose.json").write_text(json.dumps(evaluation([(0.58, True)])))
    monkeypatch.setattr(sys, "argv", ["placement_bands", str(tmp_path / "loose.json")])
    with pytest.raises(SystemExit, match="names no teacher"):
        main()
