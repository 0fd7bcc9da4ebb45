"""Shared parts of kuka-curriculum: the KUKA grasp environments, their task spaces and what the
services exchange.

Importing ``common`` registers ``KukaGrasp-v0`` (the book's task) and ``KukaGraspHard-v0`` (a harder
family around it) with gymnasium by entry-point string, so pybullet loads only when an environment
is made.
"""

import gymnasium

ENV_ID = "KukaGrasp-v0"
HARD_ENV_ID = "KukaGraspHard-v0"
ENV_IDS = (ENV_ID, HARD_ENV_ID)

for _env_id, _entry_point in (
    (ENV_ID, "common.kuka_env:KukaGraspEnv"),
    (HARD_ENV_ID, "common.kuka_env:KukaGraspHardEnv"),
):
    if _env_id not in gymnasium.registry:
        gymnasium.register(id=_env_id, entry_point=_entry_point)
