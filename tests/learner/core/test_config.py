import pytest

from common.kuka.task_space import KUKA_TASK_SPACE
from common.levels import LEVEL_ENV_IDS, level_task_space
from learner.core.config import TEACHERS, PPOConfig, TrainConfig
from teacher_service.teachers import TEACHER_KINDS, make_teacher


def test_config_survives_a_round_trip_through_a_plain_dict():
    config = TrainConfig(teacher="manual", workers=3, ppo=PPOConfig(hidden_sizes=(32, 16), target_kl=0.02))
    assert TrainConfig.from_dict(config.to_dict()) == config
    assert config.batch_size == 3 * config.envs_per_worker * config.ppo.rollout_length


def test_a_config_saved_before_angle_features_existed_loads_as_trained_on_raw_angles():
    saved = TrainConfig().to_dict()
    del saved["ppo"]["angle_features"]
    assert TrainConfig.from_dict(saved).ppo.angle_features is False
    assert TrainConfig().ppo.angle_features is True


def test_a_config_saved_before_the_student_options_existed_loads_as_trained():
    saved = TrainConfig().to_dict()
    for name in ("lr_final_fraction", "state_dependent_std", "min_log_std"):
        del saved["ppo"][name]
    assert TrainConfig.from_dict(saved).ppo == PPOConfig()
    assert (PPOConfig().lr_final_fraction, PPOConfig().state_dependent_std, PPOConfig().min_log_std) == (0, False, None)


def test_the_log_std_floor_takes_a_number_or_none_as_an_override():
    assert PPOConfig().with_overrides({"min_log_std": -2}).min_log_std == -2.0
    assert isinstance(PPOConfig().with_overrides({"min_log_std": -2}).min_log_std, float)
    assert PPOConfig(min_log_std=-2.0).with_overrides({"min_log_std": None}).min_log_std is None
    with pytest.raises(ValueError, match="cannot be"):
        PPOConfig().with_overrides({"min_log_std": "low"})


def test_a_config_saved_before_the_hard_family_existed_loads_as_trained_on_the_books_environment():
    saved = TrainConfig(env="KukaGraspHard-v0").to_dict()
    assert TrainConfig.from_dict(saved).env == "KukaGraspHard-v0"
    del saved["env"]
    assert TrainConfig.from_dict(saved).env == "KukaGrasp-v0" == TrainConfig().env


def test_a_config_saved_before_budget_steps_existed_counts_every_step_played():
    saved = TrainConfig().to_dict()
    del saved["budget_steps"]
    assert TrainConfig.from_dict(saved).budget_steps == "played" == TrainConfig().budget_steps


def test_the_budget_counts_score_only_steps_only_when_it_counts_every_step_played():
    from learner.core.checkpoint import Counters

    counters = Counters(steps=1000, score_only_steps=300)
    assert counters.budget_spent("played") == 1000
    assert counters.budget_spent("trained") == 700
    assert Counters(**{"steps": 10}).score_only_steps == 0, "counters saved before the field count none"


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: TrainConfig(teacher="Curious kind"), "teacher must be a kind's name"),
        (
            lambda: TrainConfig(env="KukaGrasp-v9"),
            "unknown environment .* expected one of KukaGrasp-v0, KukaGraspHard-v0",
        ),
        (lambda: TrainConfig(workers=0), "workers"),
        (lambda: TrainConfig(total_steps=0), "total_steps"),
        (lambda: TrainConfig(budget_steps="scored"), "budget_steps must be one of played, trained"),
        (lambda: TrainConfig(env="KukaGraspHard-v1", edge_placement_share=1.5), "edge_placement_share must be"),
        (lambda: TrainConfig(edge_placement_share=0.5), "edge_placement_share needs a hard KUKA family"),
        (lambda: PPOConfig(gamma=1.5), "gamma"),
        (lambda: PPOConfig(minibatch_size=0), "minibatch_size"),
        (lambda: PPOConfig(hidden_sizes=()), "hidden_sizes"),
        (lambda: PPOConfig(lr_final_fraction=1.5), "lr_final_fraction"),
        (lambda: PPOConfig(lr_final_fraction=-0.1), "lr_final_fraction"),
        (lambda: PPOConfig(min_log_std=-0.4), "min_log_std"),  # above the initial -0.5
        (lambda: PPOConfig(min_log_std=-6.0), "min_log_std"),  # under the state-dependent clamp
    ],
)
def test_bad_settings_are_refused_with_the_setting_named(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_every_setting_has_a_one_line_doc():
    import ast
    import inspect

    from learner.core import config as module

    tree = ast.parse(inspect.getsource(module))
    for node in (n for n in tree.body if isinstance(n, ast.ClassDef) and n.name in ("PPOConfig", "TrainConfig")):
        body = node.body
        for index, statement in enumerate(body):
            if isinstance(statement, ast.AnnAssign):
                following = body[index + 1] if index + 1 < len(body) else None
                assert isinstance(following, ast.Expr) and isinstance(following.value, ast.Constant), (
                    statement.target.id
                )
                assert "\n" not in following.value.value.strip(), statement.target.id


@pytest.mark.parametrize("teacher", TEACHERS)
def test_every_teacher_accepts_the_parameters_training_registers_it_with(teacher):
    """Over the KUKA space where the kind teaches floats; over a MiniGrid family's levels where it teaches
    integers and needs no anchors (fixed and the lesson plan need a hardest or easiest level, which the
    level space, whose seeds have no order, leaves out)."""
    if "float" in TEACHER_KINDS[teacher].parameter_types:
        make_teacher(teacher, KUKA_TASK_SPACE, seed=0, params=TrainConfig(teacher=teacher).teacher_params)
    if "integer" in TEACHER_KINDS[teacher].parameter_types and teacher not in ("fixed", "manual"):
        config = TrainConfig(teacher=teacher, env=LEVEL_ENV_IDS[0], levels=200)
        make_teacher(teacher, level_task_space(config.levels), seed=0, params=config.teacher_params)


def test_alp_gmm_sees_a_miss_and_a_grasp_at_opposite_ends_of_its_reward_range():
    low, high = TrainConfig(teacher="alp-gmm").teacher_params["reward_range"]
    zero_action_miss, grasp = -3.2, 9.0  # REFERENCE.md section 4; a grasp pays ~10 less the distance penalties
    assert low <= zero_action_miss < 0.5 * (low + high) < grasp <= high


def test_ppo_overrides_are_checked_by_name_and_type():
    config = PPOConfig().with_overrides({"entropy_coef": 0, "hidden_sizes": [32, 32], "target_kl": None})
    assert (config.entropy_coef, config.hidden_sizes, config.target_kl) == (0.0, (32, 32), None)
    assert isinstance(config.entropy_coef, float)
    with pytest.raises(ValueError, match="unknown PPO hyperparameter.*entropy"):
        PPOConfig().with_overrides({"entropy": 0.01})
    for bad in ({"update_epochs": 2.5}, {"anneal_lr": 1}, {"learning_rate": "fast"}, {"hidden_sizes": [32, "x"]}):
        with pytest.raises(ValueError, match="cannot be"):
            PPOConfig().with_overrides(bad)
    with pytest.raises(ValueError, match="update_epochs must be at least 1"):
        PPOConfig().with_overrides({"update_epochs": 0})


def test_teacher_overrides_go_on_top_of_the_kuka_parameters():
    config = TrainConfig(teacher="alp-gmm", teacher_overrides={"fit_rate": 100})
    assert config.teacher_params == {"reward_range": [-5.0, 10.0], "target_task_ratio": 0.2, "fit_rate": 100}
    assert TrainConfig.from_dict(config.to_dict()) == config
