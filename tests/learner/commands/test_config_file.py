"""A settings file, or a shipped recipe named instead of a path, sets ``train``'s and ``bakeoff``'s runs; flags
given override it. (A tune's ``best.json`` read back: tests/learner/test_tune.py.)"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from learner.commands import train
from learner.commands.config_file import RECIPE_DIR, RECIPES, SHOWN_CHARACTERS, config_path, read_config_file
from learner.core.config import TrainConfig
from learner.experiments import bakeoff

ROOT = Path(__file__).resolve().parents[3]


def train_config(*flags: str) -> TrainConfig:
    parser = argparse.ArgumentParser()
    train.add_arguments(parser)
    return train._config_from(parser.parse_args(list(flags)), TrainConfig())


def test_every_shipped_recipe_reads_and_trains_a_run_of_its_own():
    assert RECIPES, f"no recipes in {RECIPE_DIR}"
    for name in RECIPES:
        recipe = read_config_file(config_path(name))
        assert recipe.settings, name
        assert train_config("--config", name) != TrainConfig(), name


def test_the_hard_grasp_recipe_is_what_issue_80s_screen_3_trained_with_the_validated_policy():
    """The settings of screen 3's lines (benchmarks/bakeoff-hard/screen-i80-3.txt) and lever 5's choice."""
    config = train_config("--config", "hard-grasp-v1")
    assert (config.teacher, config.env, config.total_steps) == ("currot", "KukaGraspHard-v1", 6_000_000)
    assert config.policy_choice == "validated"
    assert config.ppo.world_block_offset and config.ppo.half_turn_block_yaw
    assert config.teacher_params == {
        "delta": 5.0,
        "estimate": "recent",
        "start": "easiest",
        "target": "box",
        "target_box": {"shaping": [0, 1]},
    }


def test_flags_override_a_recipe_and_another_teacher_leaves_its_teacher_parameters_out():
    config = train_config("--config", "hard-grasp-v1", "--total-steps", "1000", "--ppo", "half_turn_block_yaw=false")
    assert config.total_steps == 1000 and not config.ppo.half_turn_block_yaw and config.ppo.world_block_offset
    no_curriculum = train_config("--config", "hard-grasp-v1", "--teacher", "fixed")
    assert no_curriculum.teacher == "fixed" and no_curriculum.teacher_params == {}
    assert no_curriculum.ppo.half_turn_block_yaw and no_curriculum.policy_choice == "validated"


def test_a_bakeoff_takes_a_recipe_by_name_for_its_budget_policy_and_student():
    parser = argparse.ArgumentParser()
    bakeoff.add_arguments(parser)
    args = parser.parse_args(["--config", "hard-grasp-v1", "--teachers", "currot", "fixed"])
    assert (args.env, args.total_steps, args.policy_choice) == ("KukaGraspHard-v1", 6_000_000, "validated")
    assert dict(args.ppo) == {"world_block_offset": True, "half_turn_block_yaw": True}
    assert ("currot.target", "box") in args.teacher_params


def test_a_name_that_is_no_recipe_is_a_path_and_a_missing_file_is_refused_by_name(tmp_path, capsys):
    from kuka_curriculum import main

    assert config_path("hard-grasp-v1").parent == RECIPE_DIR
    assert config_path("hard-grasp") == Path("hard-grasp")
    assert main(["train", "--config", "hard-grasp-v2", "--run-dir", str(tmp_path / "run")]) == 2
    assert "no settings file hard-grasp-v2, and no recipe of that name: hard-grasp-v1" in capsys.readouterr().err
    assert main(["train", "--config", str(tmp_path), "--run-dir", str(tmp_path / "run")]) == 2
    assert f"cannot read the settings file {tmp_path}: Is a directory" in capsys.readouterr().err


def test_an_error_repeats_a_long_name_or_list_of_keys_cut_short(tmp_path, capsys):
    from kuka_curriculum import main

    assert main(["train", "--config", "x" * 5000, "--run-dir", str(tmp_path / "run")]) == 2
    error = capsys.readouterr().err
    assert "x" * (SHOWN_CHARACTERS - 1) + "…" in error
    assert "x" * SHOWN_CHARACTERS not in error
    many_keys = tmp_path / "many-keys.json"
    many_keys.write_text(json.dumps({f"key{index:04d}": 1 for index in range(1000)}), encoding="utf-8")
    assert main(["train", "--config", str(many_keys), "--run-dir", str(tmp_path / "run")]) == 2
    error = capsys.readouterr().err
    assert "unknown key(s) key0000, key0001" in error
    assert "key0999" not in error


@pytest.mark.parametrize("name", RECIPES)
def test_a_recipe_is_package_data_so_an_installed_wheel_has_it(name):
    """The Docker image installs the package from a wheel, not the tree: the recipe must be declared package data."""
    import tomllib

    package_data = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    patterns = package_data["package-data"]["learner.commands"]
    relative = (RECIPE_DIR / f"{name}.json").relative_to(ROOT / "learner" / "commands")
    assert any(relative.match(pattern) for pattern in patterns), patterns
    assert isinstance(json.loads((RECIPE_DIR / f"{name}.json").read_text(encoding="utf-8")), dict)
