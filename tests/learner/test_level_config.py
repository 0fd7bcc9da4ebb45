"""How a training run on a MiniGrid level family is set up: the accepted ids, the training set, the task
space it registers, the held-out evaluation levels, its categorical policy and its teacher's parameters."""

from __future__ import annotations

import pytest

from common.kuka import ENV_IDS
from common.levels import HELD_OUT_FIRST_SEED, LEVEL_ENV_IDS
from kuka_curriculum import main
from learner.core.checkpoint import Counters, save_checkpoint
from learner.core.config import TRAIN_ENV_IDS, TrainConfig
from learner.core.kuka_policy import kuka_policy_spec, policy_spec_for
from learner.core.periodic_evaluation import evaluation_seeds, evaluation_task
from learner.core.ppo import PPOLearner


def test_train_takes_the_kuka_families_and_the_listed_level_families_only():
    assert (*ENV_IDS, *LEVEL_ENV_IDS) == TRAIN_ENV_IDS
    for env in LEVEL_ENV_IDS:
        assert TrainConfig(env=env).levels == 1000
    with pytest.raises(ValueError, match="env must be one of"):
        TrainConfig(env="MiniGrid-Empty-5x5-v0")
    with pytest.raises(ValueError, match="levels must be between 1 and 10,000"):
        TrainConfig(env=LEVEL_ENV_IDS[0], levels=10_001)


def test_the_cli_refuses_an_unlisted_environment(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--env", "MiniGrid-Empty-5x5-v0"])
    assert "invalid choice: 'MiniGrid-Empty-5x5-v0'" in capsys.readouterr().err


def test_a_level_family_is_evaluated_on_held_out_levels_and_kuka_as_before():
    assert evaluation_task("MiniGrid-DoorKey-8x8-v0") == {}
    assert evaluation_seeds(3, "MiniGrid-DoorKey-8x8-v0") == [HELD_OUT_FIRST_SEED + k for k in range(3)]
    assert evaluation_seeds(2, ENV_IDS[0]) == evaluation_seeds(2) == [10_000, 10_001]


def test_a_level_familys_policy_is_categorical_over_its_view_and_kuka_keeps_its_own():
    config = TrainConfig(env="MiniGrid-KeyCorridorS3R2-v0")
    spec = policy_spec_for(config.env, config.ppo)
    assert (spec.obs_dim, spec.action_dim, spec.categorical, spec.angle_indices) == (147, 7, True, ())
    kuka = TrainConfig()
    assert policy_spec_for(kuka.env, kuka.ppo) == kuka_policy_spec(kuka.ppo)


def test_a_level_family_registers_its_teacher_without_the_kuka_parameters():
    assert TrainConfig(teacher="alp-gmm").teacher_params["reward_range"] == [-5.0, 10.0]
    config = TrainConfig(teacher="plr", env=LEVEL_ENV_IDS[0], teacher_overrides={"robust": True})
    assert config.teacher_params == {"robust": True}


@pytest.mark.parametrize("command", ["evaluate", "render"])
def test_evaluate_and_render_refuse_a_level_familys_checkpoint_in_one_line(tmp_path, capsys, command):
    config = TrainConfig(teacher="plr", env=LEVEL_ENV_IDS[0], levels=20)
    learner = PPOLearner(policy_spec_for(config.env, config.ppo), config.ppo, seed=0)
    path = save_checkpoint(tmp_path / "run", learner.state_dict(), Counters(iteration=1, steps=10), config)
    flags = ["--out", str(tmp_path / "policy.gif")] if command == "render" else []
    assert main([command, str(path), *flags]) == 2
    assert f"trained on the level family {LEVEL_ENV_IDS[0]}; evaluate and render play" in capsys.readouterr().err
