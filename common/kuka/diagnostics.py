"""Where an episode's block lay and how the gripper met it: the per-episode figures that say why a grasp
failed, read from the simulator while the episode is played.

A policy (or the scripted controller) plays one seeded episode through ``play_episode``, which records:
- the block's placement (world x, y and yaw) right after the reset;
- how far its x lies beyond the arm's reach: the IK target's x is clamped to ``TARGET_X_RANGE``, so a block
  outside it can only be grasped by hanging the fingers over its end;
- at touchdown (the first touch of the tray, which starts the scripted grasp), the block's x and y in the
  gripper's frame as the last action saw them, how far the wrist had turned by then, and the fingers' angle
  from square to the block (the environment's own ``off_square_degrees``); an episode cut at the step limit
  has none of them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.client.task_space import Task
from common.kuka.arm import TARGET_X_RANGE
from common.kuka.env import BLOCK_XY_IN_GRIPPER, KukaGraspEnv

Controller = Callable[[np.ndarray], np.ndarray]
"""Observation to action: a deterministic policy or the scripted controller."""


def beyond_clamp(block_x: float) -> float:
    """How far (metres) ``block_x`` lies outside the IK target's x range: positive outside, and inside minus
    the distance to the nearer edge, so one signed number orders placements from easy to out of reach."""
    low, high = TARGET_X_RANGE
    return max(low - block_x, block_x - high)


@dataclass(frozen=True)
class EpisodeDiagnostics:
    """One episode's placement and touchdown; the ``touchdown_*`` and ``off_square_degrees`` fields are None
    for an episode that never touched the tray."""

    block_x: float
    block_y: float
    block_yaw: float
    touchdown_block_x: float | None
    """The block's x (metres) in the gripper's frame one step before touchdown."""
    touchdown_block_y: float | None
    off_square_degrees: float | None
    """How far (degrees, 0 to 90) the fingers were from square to the block at touchdown."""
    touchdown_wrist_turn_degrees: float | None = None
    """How far (degrees, signed as the yaw actions add up) the wrist had turned from its start one step before
    touchdown; None also in results written before it was recorded."""

    @property
    def beyond_clamp(self) -> float:
        return beyond_clamp(self.block_x)

    @property
    def touchdown_offset(self) -> float | None:
        """How far (metres) the block lay from the gripper's axis in x/y at touchdown."""
        if self.touchdown_block_x is None or self.touchdown_block_y is None:
            return None
        return math.hypot(self.touchdown_block_x, self.touchdown_block_y)

    def to_dict(self) -> dict[str, float | None]:
        """Every field, and the two derived ones a reader of the JSON would otherwise recompute."""
        return {
            "block_x": self.block_x,
            "block_y": self.block_y,
            "block_yaw": self.block_yaw,
            "beyond_clamp": self.beyond_clamp,
            "touchdown_block_x": self.touchdown_block_x,
            "touchdown_block_y": self.touchdown_block_y,
            "touchdown_offset": self.touchdown_offset,
            "off_square_degrees": self.off_square_degrees,
            "touchdown_wrist_turn_degrees": self.touchdown_wrist_turn_degrees,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EpisodeDiagnostics:
        def optional(name: str) -> float | None:
            return None if data.get(name) is None else float(data[name])

        return cls(
            block_x=float(data["block_x"]),
            block_y=float(data["block_y"]),
            block_yaw=float(data["block_yaw"]),
            touchdown_block_x=optional("touchdown_block_x"),
            touchdown_block_y=optional("touchdown_block_y"),
            off_square_degrees=optional("off_square_degrees"),
            touchdown_wrist_turn_degrees=optional("touchdown_wrist_turn_degrees"),
        )


@dataclass(frozen=True)
class PlayedEpisode:
    """One episode's outcome and its diagnostics."""

    reward: float
    success: bool
    length: int
    diagnostics: EpisodeDiagnostics


def play_episode(env: KukaGraspEnv, task: Task, act: Controller, seed: int) -> PlayedEpisode:
    """Play one episode of ``act`` on ``task``, seeded ``seed``, recording where the block lay and how the
    gripper met it. Actions are clipped to the action space, as the rollout workers clip them."""
    low, high = env.action_space.low, env.action_space.high
    observation, _ = env.reset(seed=seed, options={"task": task})
    block_x, block_y, block_yaw = env.block_pose()
    total, length = 0.0, 0
    while True:
        seen, wrist_turn = observation, env.wrist_turn
        observation, reward, terminated, truncated, info = env.step(np.clip(act(observation), low, high))
        total += float(reward)
        length += 1
        if terminated or truncated:
            break
    # A terminated episode touched the tray (the only way one ends before the step limit).
    touchdown = [float(value) for value in seen[BLOCK_XY_IN_GRIPPER]] if terminated else [None, None]
    touchdown_wrist_turn = math.degrees(wrist_turn) if terminated else None
    off_square = info.get("off_square_degrees")
    diagnostics = EpisodeDiagnostics(
        block_x=block_x,
        block_y=block_y,
        block_yaw=block_yaw,
        touchdown_block_x=touchdown[0],
        touchdown_block_y=touchdown[1],
        off_square_degrees=None if off_square is None else float(off_square),
        touchdown_wrist_turn_degrees=touchdown_wrist_turn,
    )
    return PlayedEpisode(total, bool(info.get("is_success", False)), length, diagnostics)
