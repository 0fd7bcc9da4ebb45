"""A tiny continuous-control task for checking that PPO learns: move a point onto a 1-D target.

Observations are deliberately badly scaled (large offsets and spreads) so that learning also
depends on the running observation normalisation being right.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from common.client.teacher_client import Assignment
from common.policy.trajectory import EpisodeStats

OBS_SCALE = np.array([40.0, 0.05], dtype=np.float32)
OBS_OFFSET = np.array([300.0, -7.0], dtype=np.float32)


class ReachTarget(gym.Env):
    """Reward is minus the distance each step; reaching within ``tolerance`` ends the episode with +1."""

    def __init__(self, max_steps: int = 40, speed: float = 0.1, tolerance: float = 0.05) -> None:
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.max_steps, self.speed, self.tolerance = max_steps, speed, tolerance
        self.position = self.target = 0.0
        self.steps = 0

    def _observation(self) -> np.ndarray:
        return np.array([self.position, self.target], dtype=np.float32) * OBS_SCALE + OBS_OFFSET

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.position, self.target = self.np_random.uniform(-1.0, 1.0, size=2)
        self.steps = 0
        return self._observation(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.position = float(np.clip(self.position + self.speed * float(action[0]), -1.0, 1.0))
        self.steps += 1
        distance = abs(self.position - self.target)
        reached = distance < self.tolerance
        reward = 1.0 if reached else -distance
        return self._observation(), reward, reached, self.steps >= self.max_steps, {"is_success": reached}


class RecordingTasks:
    """A task source with one empty task that keeps every reported episode."""

    def __init__(self) -> None:
        self.handed_out = 0
        self.reported: list[EpisodeStats] = []

    def next_task(self) -> Assignment:
        self.handed_out += 1
        return Assignment(f"reach:{self.handed_out}", {})

    def report(self, episode: EpisodeStats) -> None:
        self.reported.append(episode)
