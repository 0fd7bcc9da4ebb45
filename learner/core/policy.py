"""The policy's network on a run's environment: its shape, one definition for training and evaluation, and
the policy a checkpoint holds."""

from __future__ import annotations

from common.families import family_for
from common.levels import DEFAULT_LEVELS
from common.policy.actor_critic import PolicySnapshot, PolicySpec
from learner.core.checkpoint import Checkpoint
from learner.core.config import PPOConfig
from learner.core.ppo import PPOLearner


def policy_spec_for(env_id: str, ppo: PPOConfig, levels: int = DEFAULT_LEVELS) -> PolicySpec:
    """The network's shape for a run on ``env_id``: its family's encoder and head, with the options of ``ppo``
    that apply there (a Gaussian's log-std; KUKA's angle features, the block's world offset and half-turn yaw;
    a critic that reads the task, as wide as the run's task space, which ``levels`` sizes for a level family)."""
    family = family_for(env_id)
    shape = family.policy_shape(env_id)
    angles = shape.angle_indices if ppo.angle_features else ()
    critic_task_dim = len(family.task_space(env_id, levels)) if ppo.critic_task_inputs else 0
    if shape.categorical:
        return PolicySpec(
            obs_dim=shape.observation_dim,
            action_dim=shape.action_dim,
            hidden_sizes=ppo.hidden_sizes,
            categorical=True,
            image_shape=shape.image_shape,
            critic_task_dim=critic_task_dim,
        )
    return PolicySpec(
        obs_dim=shape.observation_dim,
        action_dim=shape.action_dim,
        hidden_sizes=ppo.hidden_sizes,
        init_log_std=ppo.init_log_std,
        state_dependent_std=ppo.state_dependent_std,
        min_log_std=ppo.min_log_std,
        angle_indices=angles,
        world_offsets=(shape.world_offset,) if ppo.world_block_offset and shape.world_offset is not None else (),
        half_turn_indices=tuple(index for index in shape.half_turn_indices if index in angles)
        if ppo.half_turn_block_yaw
        else (),
        image_shape=shape.image_shape,
        critic_task_dim=critic_task_dim,
    )


def policy_snapshot(checkpoint: Checkpoint) -> PolicySnapshot:
    """The policy a checkpoint holds, in the form the rollout workers act with."""
    spec = policy_spec_for(checkpoint.config.env, checkpoint.config.ppo, checkpoint.config.levels)
    learner = PPOLearner(spec, checkpoint.config.ppo, checkpoint.config.seed)
    learner.load_policy_state(checkpoint.learner)
    return learner.snapshot()
