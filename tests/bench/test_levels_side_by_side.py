"""The level side-by-side (issue 79): each arm set up as its authors ship it, what each run's budget counts,
the take-off survival curves, and the driver end to end on a tiny budget. A test here fails if an arm
departs from its authors' settings: our PLR not the paper's always-replay, robust PLR not DCD's MiniGrid
settings or charged for steps it does not train on, Syllabus's Learnability not charged for its evaluator."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bench.levels_side_by_side import (
    ARMS,
    COUNTERPARTS,
    PLAN_ARMS,
    curriculum_name,
    kaplan_meier,
    parse_args,
    run_config,
    take_off_step,
    tier_table,
)
from teacher_service.teachers import make_teacher


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


def sampler_of(kind: str, levels: int = 200):
    """The level sampler the service builds for the arm (the teacher the run registers)."""
    arm = ARMS[kind]
    return make_teacher(arm.teacher, levels_space(levels), 0, dict(arm.params)).sampler


def levels_space(levels: int):
    from common.levels import level_task_space

    return level_task_space(levels)


def test_our_plr_is_the_papers_sweep_then_always_replay_scored_by_value_l1() -> None:
    sampler = sampler_of("plr")
    assert (sampler.temperature, sampler.staleness_coef, sampler.schedule) == (0.1, 0.1, "proportionate")
    assert (sampler.min_seen_share, sampler.replay_prob) == (1.0, 1.0), "a sweep of every level, then only replays"
    assert ARMS["plr"].level_score == "value_l1" and ARMS["plr"].budget_steps == "played"
    hybrid = sampler_of("plr-hybrid")
    assert hybrid.replay_prob == 0.5 and ARMS["plr-hybrid"].level_score == "value_l1", "the hybrid is named apart"


def test_robust_plr_has_dcds_minigrid_settings_and_pays_only_for_what_it_trains_on() -> None:
    sampler = sampler_of("robust-plr")
    assert (sampler.replay_prob, sampler.min_seen_share, sampler.schedule) == (0.5, 0.5, "proportionate")
    assert (sampler.temperature, sampler.staleness_coef) == (0.3, 0.3)
    assert ARMS["robust-plr"].params["robust"] is True, "no gradient on explored levels (score-only)"
    assert ARMS["robust-plr"].level_score == "positive_value_loss"
    assert ARMS["robust-plr"].budget_steps == "trained"


def test_each_run_sends_its_arms_score_and_counts_its_arms_budget() -> None:
    args = parse_args(["--out", "unused", "--steps", "1000"])
    for kind in ARMS:
        config = run_config(args, kind, 3)
        arm = ARMS[kind]
        assert config.ppo.level_score == arm.level_score and config.budget_steps == arm.budget_steps
        assert config.teacher == arm.teacher and config.teacher_overrides == dict(arm.params)
        assert (config.seed, config.total_steps, config.env, config.levels) == (3, 1000, "MiniGrid-Gamut-v0", 200)
    assert ARMS["syllabus-plr"].level_score == "value_l1", "Syllabus's example's strategy"
    assert ARMS["syllabus-learnability"].budget_steps == "played", "its evaluator's episodes are charged"
    assert set(COUNTERPARTS.values()) <= set(PLAN_ARMS) and set(COUNTERPARTS) <= set(PLAN_ARMS)
    assert "no-curriculum" not in PLAN_ARMS and "no-curriculum" in parse_args(["--out", "x", "--throughput"]).kinds


def test_a_resample_count_out_of_bounds_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    for reps in ("99", "100001"):
        with pytest.raises(SystemExit) as exit_info:
            parse_args(["--out", "unused", "--reps", reps])
        assert exit_info.value.code == 2 and "--reps" in capsys.readouterr().err


def test_take_off_is_the_first_evaluation_at_the_threshold() -> None:
    curve = {"steps": [100.0, 200.0, 300.0], "success": [0.2, 0.5, 0.9]}
    assert take_off_step(curve, 0.5) == 200.0
    assert take_off_step(curve, 0.95) is None


def test_kaplan_meier_counts_runs_that_never_take_off_as_censored_at_the_budget() -> None:
    curve = kaplan_meier([100.0, 200.0, None, None], censored_at=1000.0)
    assert curve["steps"] == [0.0, 100.0, 200.0] and curve["survival"] == pytest.approx([1.0, 0.75, 0.5])
    assert curve["median_take_off_step"] == 200.0 and (curve["runs"], curve["taken_off"]) == (4, 2)
    assert all(low <= s <= high for low, s, high in zip(curve["low"], curve["survival"], curve["high"], strict=True))
    assert kaplan_meier([None] * 3, censored_at=1000.0)["median_take_off_step"] is None
    ties = kaplan_meier([50.0, 50.0, 80.0], censored_at=100.0)
    assert ties["survival"] == pytest.approx([1.0, 1.0 / 3.0, 0.0])


def test_the_tier_table_averages_each_arms_runs_tier_by_tier() -> None:
    runs = {
        "plr": [{"success_by_tier": [1.0, 0.5] + [0.0] * 6}, {"success_by_tier": [0.5, 0.5] + [1.0] * 6}],
        "random": [{"success_by_tier": [0.25] * 8}],
    }
    table = tier_table(runs)
    header = next(line for line in table if line.startswith("| arm"))
    assert header.split(" | ")[1:3] == ["7x7 none", "7x7 gap"] and "14x14 locked" in header
    assert "| plr | 75.0 | 50.0 | 50.0 | 50.0 | 50.0 | 50.0 | 50.0 | 50.0 |" in table
    assert "| random | 25.0 | 25.0 | 25.0 | 25.0 | 25.0 | 25.0 | 25.0 | 25.0 |" in table
    assert tier_table({"plr": [{"success": 0.5}]}) == [], "off the gamut a run has no tiers"


def test_the_driver_runs_and_reports_on_a_tiny_budget(tmp_path: Path, ray_cluster: str) -> None:
    out = tmp_path / "side-by-side"
    budget = 2 * 2 * 8 * 128  # two batches
    command = [
        *(sys.executable, "bench/levels_side_by_side.py", "--out", str(out), "--env", "MiniGrid-DoorKey-5x5-v0"),
        *("--levels", "4", "--steps", str(budget), "--seeds", "0", "--kinds", "robust-plr", "syllabus-learnability"),
        *("--eval-every", "1", "--eval-episodes", "2", "--test-levels", "2", "--test-repeats", "1", "--reps", "100"),
        *("--ray-address", ray_cluster),
    ]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=Path(__file__).parents[2])
    assert done.returncode == 0, done.stdout + done.stderr

    results = json.loads((out / "results.json").read_text())
    robust = results["runs"]["robust-plr"][0]
    learnability = results["runs"]["syllabus-learnability"][0]
    # Robust PLR: its score-only episodes are played but not charged; it stops once it has trained the budget.
    assert (
        robust["steps_score_only"] > 0
        and robust["steps_played"] == robust["steps_trained"] + robust["steps_score_only"]
    )
    assert robust["budget_spent"] == robust["steps_trained"] >= budget
    # Syllabus's Learnability: its evaluator's episodes (score-only, on the workers) count in its budget.
    assert learnability["steps_score_only"] > 0 and learnability["syllabus"]["evaluations"] >= 1
    assert learnability["budget_spent"] == learnability["steps_played"] >= budget
    invocation = results["invocations"][0]
    assert "levels_side_by_side.py" in invocation["command"] and invocation["machine"]["cpus"] >= 1
    assert invocation["started"] and robust["started"] and robust["finished"] and robust["commit"]
    assert results["layouts"]["held_out_levels"] == 2
    assert set(results["statistics"]["arms"]) == {"robust-plr", "syllabus-learnability"}
    assert results["against_counterpart"] == {}, "robust PLR's counterpart, Syllabus's PLR, did not run"
    assert set(results["survival"]) == {"robust-plr", "syllabus-learnability"}
    for picture in ("performance_profile.png", "take_off_survival.png", "learning_curves.png"):
        assert (out / picture).stat().st_size > 0
    assert "| robust-plr | 1 |" in (out / "results.md").read_text()
