import numpy as np
import pytest

from common.kuka import HARD_V1_ENV_ID
from common.kuka.env import make_kuka_env
from common.policy.inference import ObservationFeatures
from learner.config import PPOConfig, TrainConfig
from learner.kuka_policy import kuka_policy_spec


def test_the_world_block_offset_is_where_the_simulator_has_the_block_from_the_gripper():
    spec = kuka_policy_spec(PPOConfig(world_block_offset=True))
    features = ObservationFeatures(spec)
    env = make_kuka_env(HARD_V1_ENV_ID)
    rng = np.random.default_rng(0)
    try:
        errors = []
        for seed in range(3):
            observation, _ = env.reset(seed=seed)
            for _ in range(150):  # the wrist turns and the gripper moves, so the frames part
                observation, _, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, size=3))
                block_x, block_y, _ = env.block_pose()
                world_offset = np.array([block_x - observation[0], block_y - observation[1]])
                errors.append(np.abs(features(observation[None])[0, -2:] - world_offset).max())
                if terminated or truncated:
                    break
    finally:
        env.close()
    assert max(errors) < 2e-3  # metres: float32 observations, and the block's height in the gripper's frame left out


def test_without_the_option_the_networks_inputs_are_as_before():
    plain, extended = kuka_policy_spec(PPOConfig()), kuka_policy_spec(PPOConfig(world_block_offset=True))
    assert plain.world_offsets == ()
    assert plain.feature_dim == 9 + 4
    assert extended.feature_dim == plain.feature_dim + 2
    assert ObservationFeatures(extended)(np.zeros((1, 9), dtype=np.float32)).shape == (1, 15)


@pytest.mark.parametrize("value", [True, False])
def test_the_option_survives_a_checkpoints_config_round_trip(value):
    config = TrainConfig(ppo=PPOConfig(world_block_offset=value))
    assert TrainConfig.from_dict(config.to_dict()).ppo.world_block_offset is value
