"""A hand-made controller for the KUKA grasp: the yardstick a learnt policy is read against.

It reads only the observation, moves the gripper over the block and turns the fingers across it. It
shows what a point of a task family allows (it grasps far blocks by hanging over their end), not how
well PPO can do; ``evaluate --scripted`` and the bake-off play it on the learnt policies' own seeds.
"""

from __future__ import annotations

import math

import numpy as np

from common.kuka.env import off_square

SCRIPT_GAIN = 100.0
"""Action per metre of x/y offset (saturates beyond 1 cm)."""
SCRIPT_YAW_GAIN = 5.0
"""Wrist action per radian of misalignment."""


def scripted_action(observation: np.ndarray) -> np.ndarray:
    """Move over the block and turn the fingers across it, from the observation alone.

    The block's offset in the gripper's frame (entries 6 and 7) maps to the world by the gripper's yaw
    (entry 5), the gripper pointing down; the fingers close across the block when its yaw in the
    gripper's frame (entry 8) is pi/2, modulo pi.
    """
    yaw, block_x, block_y, block_yaw = (float(value) for value in observation[5:9])
    cos, sin = math.cos(yaw), math.sin(yaw)
    world_dx, world_dy = cos * block_x + sin * block_y, sin * block_x - cos * block_y
    wanted = np.array([SCRIPT_GAIN * world_dx, SCRIPT_GAIN * world_dy, SCRIPT_YAW_GAIN * off_square(block_yaw)])
    action: np.ndarray = np.clip(wanted, -1.0, 1.0).astype(np.float32)
    return action
