"""How a training run on a MiniGrid level family is set up: the accepted ids, the training set, the task
space it registers, the held-out evaluation levels, its categorical policy and its teacher's parameters."""

from __future__ import annotations

import pytest

from common.families.base import HELD_OUT_FIRST_SEED
from common.kuka import ENV_ID, ENV_IDS
from common.levels import LEVEL_ENV_IDS
from kuka_curriculum import main
from learner.core.config import LISTED_ENV_IDS, TrainConfig
from learner.core.policy import policy_spec_for


def test_train_lists_the_kuka_families_then_the_level_families_and_refuses_other_plain_ids():
    assert (*ENV_IDS, *LEVEL_ENV_IDS) == LISTED_ENV_IDS
    for env in LEVEL_ENV_IDS:
        assert TrainConfig(env=env).levels == 1000
    with pytest.raises(ValueError, match="unknown environment 'MiniGrid-Empty-5x5-v0'; expected one of"):
        TrainConfig(env="MiniGrid-Empty-5x5-v0")
    with pytest.raises(ValueError, match="levels must be between 1 and 10,000"):
        TrainConfig(env=LEVEL_ENV_IDS[0], levels=10_001)


def test_the_cli_refuses_an_unlisted_environment(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--env", "MiniGrid-Empty-5x5-v0"])
    assert "unknown environment 'MiniGrid-Empty-5x5-v0'" in capsys.readouterr().err


def test_a_level_family_is_evaluated_on_held_out_levels_and_kuka_as_before():
    level = TrainConfig(env="MiniGrid-DoorKey-8x8-v0", eval_episodes=3)
    assert level.evaluation_task() == {}
    assert level.evaluation_seeds() == [HELD_OUT_FIRST_SEED + k for k in range(3)]
    kuka = TrainConfig(env=ENV_IDS[0], eval_episodes=2, eval_seeds="consecutive")
    assert kuka.evaluation_seeds() == [10_000, 10_001]


def test_a_level_familys_policy_is_categorical_over_its_view_and_kuka_keeps_its_own():
    config = TrainConfig(env="MiniGrid-KeyCorridorS3R2-v0")
    spec = policy_spec_for(config.env, config.ppo)
    assert (spec.obs_dim, spec.action_dim, spec.categorical, spec.angle_indices) == (147, 7, True, ())
    kuka = policy_spec_for(ENV_ID, TrainConfig().ppo)
    assert (kuka.obs_dim, kuka.action_dim, kuka.categorical, kuka.angle_indices) == (9, 3, False, (3, 4, 5, 8))


def test_a_level_family_registers_its_teacher_without_the_kuka_parameters():
    assert TrainConfig(teacher="alp-gmm").teacher_params["reward_range"] == [-5.0, 10.0]
    config = TrainConfig(teacher="plr", env=LEVEL_ENV_IDS[0], teacher_overrides={"robust": True})
    assert config.teacher_params == {"robust": True}
