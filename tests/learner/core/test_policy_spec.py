import numpy as np
import pytest

from common.kuka import ENV_ID, HARD_V1_ENV_ID
from common.kuka.env import BLOCK_Z, make_kuka_env
from common.policy.inference import ObservationFeatures
from learner.core.config import PPOConfig, TrainConfig
from learner.core.policy import policy_spec_for


def test_the_world_block_offset_is_where_the_simulator_has_the_block_from_the_gripper():
    spec = policy_spec_for(ENV_ID, PPOConfig(world_block_offset=True))
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
    plain, extended = policy_spec_for(ENV_ID, PPOConfig()), policy_spec_for(ENV_ID, PPOConfig(world_block_offset=True))
    assert plain.world_offsets == ()
    assert plain.feature_dim == 9 + 4
    assert extended.feature_dim == plain.feature_dim + 2
    assert ObservationFeatures(extended)(np.zeros((1, 9), dtype=np.float32)).shape == (1, 15)


@pytest.mark.parametrize("value", [True, False])
def test_the_option_survives_a_checkpoints_config_round_trip(value):
    config = TrainConfig(ppo=PPOConfig(world_block_offset=value))
    assert TrainConfig.from_dict(config.to_dict()).ppo.world_block_offset is value


@pytest.mark.parametrize("half_turn", [True, False])
def test_with_half_turn_block_yaw_a_block_turned_half_a_turn_looks_the_same_to_the_networks(half_turn):
    features = ObservationFeatures(
        policy_spec_for(ENV_ID, PPOConfig(world_block_offset=True, half_turn_block_yaw=half_turn))
    )
    env = make_kuka_env(HARD_V1_ENV_ID)
    try:
        env.reset(seed=3)
        client = env.unwrapped._client
        block_x, block_y, block_yaw = env.block_pose()
        inputs = []
        for yaw in (block_yaw, block_yaw + np.pi):
            orientation = client.getQuaternionFromEuler((0.0, 0.0, yaw))
            client.resetBasePositionAndOrientation(env.unwrapped._block, (block_x, block_y, BLOCK_Z), orientation)
            observation, _ = env.unwrapped._observe()
            inputs.append(features(observation[None])[0])
    finally:
        env.close()
    difference = np.abs(inputs[0] - inputs[1]).max()
    if half_turn:
        assert difference < 1e-4
    else:
        assert difference > 1.0  # the block's (sin, cos) flip sign


def test_half_turn_block_yaw_needs_angle_features():
    with pytest.raises(ValueError, match="half_turn_block_yaw needs angle_features"):
        PPOConfig(angle_features=False, half_turn_block_yaw=True)


@pytest.mark.parametrize("value", [True, False])
def test_half_turn_block_yaw_survives_a_checkpoints_config_round_trip(value):
    config = TrainConfig(ppo=PPOConfig(half_turn_block_yaw=value))
    assert TrainConfig.from_dict(config.to_dict()).ppo.half_turn_block_yaw is value
