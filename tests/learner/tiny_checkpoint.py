"""A real checkpoint, in the format training writes, of a small untrained policy."""

from __future__ import annotations

from pathlib import Path

from common.kuka_env import KukaGraspEnv
from common.policy import PolicySpec
from learner.checkpoint import Counters, save_checkpoint
from learner.config import PPOConfig, TrainConfig
from learner.ppo import PPOLearner

TINY_EPISODE_STEPS = 40


def save_untrained_checkpoint(run_dir: Path, seed: int = 0) -> Path:
    config = TrainConfig(teacher="fixed", seed=seed, max_episode_steps=TINY_EPISODE_STEPS,
                         ppo=PPOConfig(hidden_sizes=(16, 16)))
    env = KukaGraspEnv()
    spec = PolicySpec(obs_dim=env.observation_space.shape[0], action_dim=env.action_space.shape[0],
                      hidden_sizes=config.ppo.hidden_sizes, init_log_std=config.ppo.init_log_std)
    env.close()
    learner = PPOLearner(spec, config.ppo, seed)
    return save_checkpoint(run_dir, learner.state_dict(), Counters(iteration=1, steps=512, episodes=4), config)
