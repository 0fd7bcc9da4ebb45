"""A real checkpoint, in the format training writes, of a small untrained policy."""

from __future__ import annotations

from pathlib import Path

from common.kuka import ENV_ID
from learner.core.checkpoint import Counters, save_checkpoint
from learner.core.config import PPOConfig, TrainConfig
from learner.core.policy import policy_spec_for
from learner.core.ppo import PPOLearner

TINY_EPISODE_STEPS = 40


def save_untrained_checkpoint(run_dir: Path, seed: int = 0, env: str = ENV_ID) -> Path:
    config = TrainConfig(
        teacher="fixed",
        env=env,
        seed=seed,
        max_episode_steps=TINY_EPISODE_STEPS,
        ppo=PPOConfig(hidden_sizes=(16, 16)),
    )
    learner = PPOLearner(policy_spec_for(ENV_ID, config.ppo), config.ppo, seed)
    return save_checkpoint(run_dir, learner.state_dict(), Counters(iteration=1, steps=512, episodes=4), config)
