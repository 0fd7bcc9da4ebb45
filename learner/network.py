"""The policy network's shape for the KUKA environment: one definition for training and evaluation."""

from __future__ import annotations

from common.kuka_env import KukaGraspEnv
from common.policy import PolicySpec
from learner.config import PPOConfig


def kuka_policy_spec(ppo: PPOConfig) -> PolicySpec:
    probe = KukaGraspEnv()
    try:
        return PolicySpec(
            obs_dim=probe.observation_space.shape[0],
            action_dim=probe.action_space.shape[0],
            hidden_sizes=ppo.hidden_sizes,
            init_log_std=ppo.init_log_std,
            angle_indices=probe.angle_indices if ppo.angle_features else (),
        )
    finally:
        probe.close()
