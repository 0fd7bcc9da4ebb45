"""Shared parts of kuka-curriculum: the KUKA grasp environment, the task space and what the
services exchange.

Importing ``common`` registers ``KukaGrasp-v0`` with gymnasium by entry-point string, so pybullet
loads only when an environment is made.
"""

import gymnasium

ENV_ID = "KukaGrasp-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="common.kuka_env:KukaGraspEnv")
