"""A MiniGrid environment as the rollout workers step it: the level is the reset seed, the observation
the agent's view flattened, success a positive return.

The observation is MiniGrid's egocentric image (``minigrid.wrappers.ImgObsWrapper``): 7 x 7 cells in
front of the agent, each (object, colour, state) codes, flattened to 147 floats for the project's MLP
actor-critic. Those codes are categories, not pixels: the running observation normaliser scales each cell's
codes, and MLPs on this flattened view learn the small DoorKey and MultiRoom levels (Stable-Baselines3's
``MlpPolicy`` in ``examples/sb3_minigrid_plr.py`` does the same); the policy's CNN is for pixel images.
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium
import minigrid  # noqa: F401  # registers the MiniGrid environments
import numpy as np
from minigrid.wrappers import ImgObsWrapper

import common.levels.gamut  # noqa: F401  # registers the level gamut
from common.levels import LEVEL_ENV_IDS


class LevelEnv(gymnasium.Wrapper[np.ndarray, np.int64, Any, Any]):
    """Resets with the task's ``level`` as the seed (a reset with no task uses the seed it is given: held-out
    levels), flattens the image to float32, says at an episode's end whether it reached the goal
    (``is_success``: MiniGrid pays a positive reward for that alone), and cuts episodes at ``max_steps``
    where that is below MiniGrid's own limit (which also scales its reward, so it is kept otherwise)."""

    def __init__(self, env: gymnasium.Env[Any, Any], max_steps: int | None = None) -> None:
        super().__init__(ImgObsWrapper(env))  # type: ignore[no-untyped-call]  # minigrid leaves it unannotated
        shape = self.env.observation_space.shape
        assert shape is not None
        size = int(np.prod(shape))
        self.observation_space = gymnasium.spaces.Box(0.0, 255.0, (size,), np.float32)
        self.max_steps = max_steps
        self._steps = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        task = (options or {}).get("task") or {}
        level = task.get("level")
        self._steps = 0
        observation, info = self.env.reset(seed=int(level) if level is not None else seed)
        return self._flat(observation), info

    def step(self, action: np.int64) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._steps += 1
        truncated = truncated or (self.max_steps is not None and self._steps >= self.max_steps)
        if terminated or truncated:
            info = {**info, "is_success": float(reward) > 0}
        return self._flat(observation), reward, terminated, truncated, info

    @staticmethod
    def _flat(image: np.ndarray) -> np.ndarray:
        return np.asarray(image, dtype=np.float32).reshape(-1)


def make_level_env(env_id: str, max_steps: int | None = None, render_mode: str | None = None) -> LevelEnv:
    """A level family's environment (one of ``LEVEL_ENV_IDS``), cut at ``max_steps`` if that is sooner;
    ``render_mode="rgb_array"`` draws MiniGrid's full view for ``render``."""
    if env_id not in LEVEL_ENV_IDS:
        raise ValueError(f"unknown level environment {env_id!r}; expected one of {', '.join(LEVEL_ENV_IDS)}")
    return LevelEnv(gymnasium.make(env_id, render_mode=render_mode), max_steps=max_steps)
