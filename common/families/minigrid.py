"""The MiniGrid level families (``common.levels``): the level is the reset seed, a training set of N levels
the seeds 0 to N - 1, evaluated on held-out seeds; minigrid loads only when an environment is made."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from common.client.task_space import TaskSpace
from common.families.base import PolicyShape, TaskFamily, shape_of_spaces
from common.levels import LEVEL_ENV_IDS, level_task_space


class MiniGridFamily(TaskFamily):
    """MiniGrid's procedurally generated layouts, success a positive return (``common.levels.env``).

    Evaluations sample the categorical policy's actions: its likeliest action alone can turn on the spot for
    ever. Curricula take the teacher kinds' own defaults."""

    name = "MiniGrid levels"
    deterministic_evaluation = False

    def owns(self, env_id: str) -> bool:
        return env_id in LEVEL_ENV_IDS

    def env_ids(self) -> tuple[str, ...]:
        return LEVEL_ENV_IDS

    def make_env(
        self,
        env_id: str,
        max_steps: int,
        render_mode: str | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> gym.Env[np.ndarray, Any]:
        from common.levels.env import make_level_env  # here: minigrid loads only for a level family

        return make_level_env(env_id, max_steps=max_steps, render_mode=render_mode)

    def task_space(self, env_id: str, levels: int) -> TaskSpace:
        return level_task_space(levels)

    def policy_shape(self, env_id: str) -> PolicyShape:
        """A categorical head over the flattened egocentric view (an MLP: see ``common.levels.env``)."""
        probe = self.make_env(env_id, max_steps=1)
        try:
            return shape_of_spaces(probe.observation_space, probe.action_space)
        finally:
            probe.close()  # type: ignore[no-untyped-call]  # gymnasium's Env.close is unannotated
