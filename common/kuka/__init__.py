"""The simulated KUKA grasp environments: the arm, the physics helpers, the task spaces and the demo.

Importing ``common.kuka`` registers ``KukaGrasp-v0`` (the book's task), ``KukaGraspHard-v0`` (a
harder family around it) and ``KukaGraspHard-v1`` (the same family with a tighter hardest alignment
margin) with gymnasium; pybullet loads only when an environment is made.
"""

from __future__ import annotations

from typing import Any

import gymnasium

from common.kuka.env_ids import ENV_ID, ENV_IDS, HARD_ENV_ID, HARD_V1_ENV_ID


def _grasp_env(**kwargs: Any) -> gymnasium.Env[Any, Any]:
    from common.kuka.env import KukaGraspEnv  # here, not above: the environment module loads pybullet

    return KukaGraspEnv(**kwargs)


def _hard_grasp_env(**kwargs: Any) -> gymnasium.Env[Any, Any]:
    from common.kuka.env import KukaGraspHardEnv

    return KukaGraspHardEnv(**kwargs)


def _hard_v1_grasp_env(**kwargs: Any) -> gymnasium.Env[Any, Any]:
    from common.kuka.env import KukaGraspHardV1Env

    return KukaGraspHardV1Env(**kwargs)


for _env_id, _entry_point in (
    (ENV_ID, _grasp_env),
    (HARD_ENV_ID, _hard_grasp_env),
    (HARD_V1_ENV_ID, _hard_v1_grasp_env),
):
    if _env_id not in gymnasium.registry:
        gymnasium.register(id=_env_id, entry_point=_entry_point)

__all__ = ["ENV_ID", "ENV_IDS", "HARD_ENV_ID", "HARD_V1_ENV_ID"]
