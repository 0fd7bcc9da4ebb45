"""``bench/success_by_turn.py`` splits ``evaluate --json`` files by the block's turn (modulo a
half turn) and x band: one column per file, the scripted controller's file named as such,
files of other seeds refused."""

from __future__ import annotations

import json
import lzma
import math

import pytest

from bench.success_by_turn import main, turn_sense
from common.kuka import HARD_V1_ENV_ID
from common.kuka.diagnostics import EpisodeDiagnostics
from common.kuka.task_space import KUKA_HARD_V1_TASK_SPACE
from common.policy.trajectory import EpisodeStats
from learner.evaluation.checkpoint_evaluation import EvaluationResult

TASK = KUKA_HARD_V1_TASK_SPACE.hardest()


def evaluation(placed: list[tuple[float, float, bool]], seed: int = 100000) -> dict:
    """Episodes of (block x, block yaw, success), each touching down 2 cm from the block, the wrist turned -40°."""
    episodes = tuple(EpisodeStats(TASK, 1.0, success, 800) for _, _, success in placed)
    diagnostics = tuple(EpisodeDiagnostics(x, 0.2, yaw, 0.02, 0.0, 1.0, -40.0) for x, yaw, _ in placed)
    return EvaluationResult(TASK, seed, episodes, HARD_V1_ENV_ID, diagnostics).to_dict()


@pytest.mark.parametrize(
    ("yaw", "sense"),
    [(-0.3, "clockwise"), (0.3, "anticlockwise"), (math.pi - 0.3, "clockwise"), (-math.pi + 0.3, "anticlockwise")],
)
def test_a_block_turned_half_a_turn_more_is_turned_the_same_way(yaw, sense):
    assert turn_sense(yaw) == sense


def test_each_file_is_a_column_split_by_turn_and_x(tmp_path, capsys):
    run = tmp_path / "currot-seed0"
    run.mkdir()
    # Near the arm: a clockwise block missed, an anticlockwise one (yaw pi - 0.3 is clockwise too) lifted.
    # As a committed bake-off run keeps it: compressed.
    (run / "evaluation.json.xz").write_bytes(
        lzma.compress(
            json.dumps(
                evaluation([(0.47, -0.3, False), (0.47, math.pi - 0.3, False), (0.47, 0.3, True), (0.68, 0.3, True)])
            ).encode()
        )
    )
    scripted = tmp_path / "scripted.json"
    scripted.write_text(
        json.dumps(
            {
                "controller": "scripted",
                **evaluation([(0.47, -0.3, True), (0.47, math.pi - 0.3, True), (0.47, 0.3, True), (0.68, 0.3, True)]),
            }
        )
    )
    main([str(run / "evaluation.json.xz"), str(scripted)])
    printed = capsys.readouterr().out
    assert "| block | currot-seed0 | scripted controller |" in printed
    assert "| clockwise, x < 0.5 | 0% (2), 2.0 cm, wrist -40° | 100% (2), 2.0 cm, wrist -40° |" in printed
    assert "| anticlockwise, x < 0.5 | 100% (1), 2.0 cm, wrist -40° |" in printed
    assert "| anticlockwise, x ≥ 0.65 | 100% (1)" in printed
    assert "| clockwise, 0.5 ≤ x < 0.6 | — | — |" in printed
    assert "| all | 50% (4)" in printed

    other = tmp_path / "other.json"
    other.write_text(json.dumps(evaluation([(0.47, 0.3, True)], seed=0)))
    with pytest.raises(SystemExit, match="played other episodes"):
        main([str(run / "evaluation.json.xz"), str(other)])
