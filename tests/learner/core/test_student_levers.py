"""The levers on the student and its updates (issue 80): each is a setting that ``train`` switches, that a
checkpoint's config keeps, and that is off in checkpoints from before it existed."""

import argparse
import dataclasses

import numpy as np
import pytest

from common.kuka import ENV_ID, HARD_V1_ENV_ID
from common.policy.inference import InferencePolicy
from learner.commands.train import add_arguments
from learner.core.checkpoint import Counters, load_checkpoint, save_checkpoint
from learner.core.config import PPOConfig, TrainConfig
from learner.core.policy import policy_snapshot, policy_spec_for
from learner.core.ppo import PPOLearner
from learner.core.trainer import Trainer

NEW_SWITCHES = ("critic_task_inputs", "normalize_values")


def train_flags(*flags: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return parser.parse_args(list(flags))


def test_every_lever_is_switched_from_train():
    """The new switches, and the knobs the issue lists that existed before: a learning rate with a floor, a
    target KL, an entropy bonus, and more episodes per update from more environments and shorter rollouts."""
    levers = {
        "critic_task_inputs": True,
        "normalize_values": True,
        "lr_final_fraction": 0.1,
        "target_kl": 0.02,
        "entropy_coef": 0.001,
    }
    args = train_flags(
        *(word for name in levers for word in ("--ppo", f"{name}={str(levers[name]).lower()}")),
        *("--envs-per-worker", "8", "--rollout-length", "256"),
    )
    ppo = PPOConfig().with_overrides(dict(args.ppo))
    assert {name: getattr(ppo, name) for name in levers} == levers
    assert (args.envs_per_worker, args.rollout_length) == (8, 256)


@pytest.mark.parametrize("name", NEW_SWITCHES)
def test_a_new_switch_is_off_by_default_and_survives_a_checkpoints_config_round_trip(name):
    assert getattr(PPOConfig(), name) is False
    for value in (True, False):
        config = TrainConfig(ppo=PPOConfig(**{name: value}))
        assert getattr(TrainConfig.from_dict(config.to_dict()).ppo, name) is value
    saved = TrainConfig().to_dict()
    del saved["ppo"][name]  # a checkpoint from before the switch existed
    assert getattr(TrainConfig.from_dict(saved).ppo, name) is False


@pytest.mark.parametrize("name", NEW_SWITCHES)
def test_a_new_switch_takes_true_or_false_only(name):
    with pytest.raises(ValueError, match=f"{name} must be true or false"):
        PPOConfig(**{name: "true"})
    with pytest.raises(ValueError, match=f"PPO hyperparameter {name} cannot be 1"):
        PPOConfig().with_overrides({name: 1})


@pytest.mark.parametrize(
    ("env_id", "width"),
    [(ENV_ID, 6), (HARD_V1_ENV_ID, 10), ("MiniGrid-DoorKey-5x5-v0", 1)],
    ids=["book", "hard", "levels"],
)
def test_the_critic_reads_as_many_task_inputs_as_the_runs_task_space_has_parameters(env_id, width):
    config = TrainConfig(env=env_id, levels=20, ppo=PPOConfig(critic_task_inputs=True))
    spec = policy_spec_for(env_id, config.ppo, config.levels)
    assert spec.critic_task_dim == width == len(config.task_space())
    assert policy_spec_for(env_id, PPOConfig()).critic_task_dim == 0
    assert spec == dataclasses.replace(policy_spec_for(env_id, PPOConfig(), config.levels), critic_task_dim=width)


def test_a_run_whose_critic_reads_the_task_hands_its_workers_the_task_space(tmp_path):
    config = TrainConfig(env=HARD_V1_ENV_ID, ppo=PPOConfig(critic_task_inputs=True))
    assert Trainer(config, tmp_path, "http://127.0.0.1:1", "run").worker_settings().task_space == config.task_space()
    assert Trainer(TrainConfig(), tmp_path, "http://127.0.0.1:1", "run").worker_settings().task_space is None


def test_a_checkpoint_with_both_switches_on_gives_back_the_policy_it_saved(tmp_path):
    config = TrainConfig(env=HARD_V1_ENV_ID, ppo=PPOConfig(critic_task_inputs=True, normalize_values=True))
    learner = PPOLearner(policy_spec_for(config.env, config.ppo, config.levels), config.ppo, seed=0)
    assert learner.value_statistics is not None
    learner.value_statistics.update(np.array([[2.0], [9.0], [4.0]]))
    path = save_checkpoint(tmp_path, learner.state_dict(), Counters(iteration=1, steps=10), config)

    snapshot = policy_snapshot(load_checkpoint(path))
    rng = np.random.default_rng(0)
    observations = rng.normal(size=(5, snapshot.spec.obs_dim)).astype(np.float32)
    tasks = rng.uniform(size=(5, 10)).astype(np.float32)
    expected = InferencePolicy(learner.snapshot()).value(observations, tasks)
    assert np.array_equal(InferencePolicy(snapshot).value(observations, tasks), expected)
