"""A hard KUKA run's ``edge_placement_share`` reaches the environments its workers train on, and only those:
the workers' evaluation environments, like every final evaluation, keep the task's own placement draw."""

from __future__ import annotations

from pathlib import Path

from common.families import family_for
from common.kuka import HARD_V1_ENV_ID
from common.kuka.diagnostics import beyond_clamp
from common.kuka.env import KukaGraspEnv
from learner.core.config import TrainConfig
from learner.core.trainer import Trainer

SEEDS = range(40)


def block_x_at_the_hardest_task(env: KukaGraspEnv) -> list[float]:
    xs = []
    for seed in SEEDS:
        env.reset(seed=seed)  # no task given: the family's hardest
        xs.append(env.block_pose()[0])
    env.close()
    return xs


def test_a_runs_edge_placement_share_reaches_its_training_environments_only(tmp_path: Path) -> None:
    config = TrainConfig(env=HARD_V1_ENV_ID, edge_placement_share=1.0, workers=1)
    settings = Trainer(config, tmp_path, "http://127.0.0.1:9", "unused").worker_settings()
    assert settings.env_options == {"edge_placement_share": 1.0}
    family = family_for(settings.env_id)
    training = family.make_env(settings.env_id, settings.max_episode_steps, options=settings.env_options)
    evaluation = family.make_env(settings.env_id, settings.max_episode_steps)  # as ``RolloutWorker.evaluate`` does
    assert isinstance(training, KukaGraspEnv) and isinstance(evaluation, KukaGraspEnv)
    assert all(beyond_clamp(x) > 0 for x in block_x_at_the_hardest_task(training))
    assert sum(beyond_clamp(x) <= 0 for x in block_x_at_the_hardest_task(evaluation)) >= 5
