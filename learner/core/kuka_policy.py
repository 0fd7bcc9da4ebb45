"""The KUKA policy: its network's shape, one definition for training and evaluation, and the policy
a checkpoint holds; ``policy_spec_for`` gives a level family's (MiniGrid's) too."""

from __future__ import annotations

from common.kuka.env import BLOCK_XY_IN_GRIPPER, BLOCK_YAW_INDEX, GRIPPER_EULER_INDICES, KukaGraspEnv
from common.levels import is_level_env
from common.policy.actor_critic import PolicySnapshot, PolicySpec
from common.policy.inference import WorldOffset
from learner.core.checkpoint import Checkpoint
from learner.core.config import PPOConfig
from learner.core.ppo import PPOLearner

BLOCK_OFFSET = WorldOffset(BLOCK_XY_IN_GRIPPER.start, BLOCK_XY_IN_GRIPPER.start + 1, GRIPPER_EULER_INDICES)
"""The block's (x, y) in the gripper's frame, which ``PPOConfig.world_block_offset`` turns into the world's."""


def kuka_policy_spec(ppo: PPOConfig) -> PolicySpec:
    probe = KukaGraspEnv()
    try:
        return PolicySpec(
            obs_dim=probe.observation_space.shape[0],
            action_dim=probe.action_space.shape[0],
            hidden_sizes=ppo.hidden_sizes,
            init_log_std=ppo.init_log_std,
            state_dependent_std=ppo.state_dependent_std,
            min_log_std=ppo.min_log_std,
            angle_indices=probe.angle_indices if ppo.angle_features else (),
            world_offsets=(BLOCK_OFFSET,) if ppo.world_block_offset else (),
            half_turn_indices=(BLOCK_YAW_INDEX,) if ppo.half_turn_block_yaw else (),
        )
    finally:
        probe.close()


def level_policy_spec(env_id: str, ppo: PPOConfig) -> PolicySpec:
    """A level family's policy: a categorical head over its ``Discrete`` actions, on its flattened view (see
    ``common.levels.env``); the KUKA options of ``PPOConfig`` (angles, the block's offset, the log-std's)
    do not apply."""
    from common.levels.env import action_count, make_level_env  # here: minigrid loads only for a level family

    probe = make_level_env(env_id)
    try:
        observation_shape = probe.observation_space.shape
        assert observation_shape is not None
        return PolicySpec(
            obs_dim=int(observation_shape[0]),
            action_dim=action_count(probe),
            hidden_sizes=ppo.hidden_sizes,
            categorical=True,
        )
    finally:
        probe.close()  # type: ignore[no-untyped-call]  # gymnasium's Wrapper.close is unannotated


def policy_spec_for(env_id: str, ppo: PPOConfig) -> PolicySpec:
    """The network's shape for a run on ``env_id``: a KUKA family's or a level family's."""
    return level_policy_spec(env_id, ppo) if is_level_env(env_id) else kuka_policy_spec(ppo)


def policy_snapshot(checkpoint: Checkpoint) -> PolicySnapshot:
    """The policy a checkpoint holds, in the form the rollout workers act with."""
    spec = policy_spec_for(checkpoint.config.env, checkpoint.config.ppo)
    learner = PPOLearner(spec, checkpoint.config.ppo, checkpoint.config.seed)
    learner.load_policy_state(checkpoint.learner)
    return learner.snapshot()
