"""Any gymnasium environment with a task space, named by gymnasium's own ``module:EnvId`` syntax
(``train --env my_package.envs:MyTask-v0``): the module is imported, and registers the id, when the
environment is first made.

The contract, which asks nothing of this project (docs/own-environment.md):

- the unwrapped environment has a ``task_space`` attribute, a list of parameters in the JSON form the
  service's registration takes (``name``, ``low``, ``high``, optional ``hardest``, ``easiest`` and ``type``:
  ``float`` or ``integer``);
- tasks arrive as ``reset(options={"task": {...}})``; evaluations of a space of integer parameters alone (levels)
  reset with no task, on held-out seeds;
- success is ``info["is_success"]`` at an episode's end, as Stable-Baselines3 reads it;
- observations are a flat ``Box`` (an MLP) or an image ``Box`` (height x width x channels, ``uint8``: a CNN);
  actions ``Discrete`` (a categorical head) or a flat ``Box`` (a Gaussian).

As uvicorn does for its app, the current directory is put first on the import path, so a module beside the
command imports without ``PYTHONPATH``; Ray's workers and ``evaluate``'s processes inherit that path.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Mapping
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from pydantic import ValidationError

from common.client.schemas import CurriculumSpecBase
from common.client.task_space import TaskSpace
from common.families.base import PolicyShape, TaskFamily, UnusableEnvironment, shape_of_spaces

TASK_SPACE_ATTRIBUTE = "task_space"


class TaskEnvironment(gym.Wrapper[np.ndarray, Any, Any, Any]):
    """A user's environment as the workers step it: its observation flat ``float32``, an empty task not passed
    on (a reset with no task), episodes cut at ``max_steps``, and ``is_success`` always present at an end."""

    def __init__(self, env: gym.Env[Any, Any], max_steps: int) -> None:
        super().__init__(env)
        shape = env.observation_space.shape
        assert shape is not None, "checked by shape_of_spaces"
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (int(np.prod(shape)),), np.float32)
        self.max_steps = max_steps
        self._steps = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        options = dict(options or {})
        if not options.get("task"):
            options.pop("task", None)
        self._steps = 0
        observation, info = self.env.reset(seed=seed, options=options or None)
        return _flat(observation), info

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._steps += 1
        truncated = truncated or self._steps >= self.max_steps
        if terminated or truncated:
            info = {**info, "is_success": bool(info.get("is_success", False))}
        return _flat(observation), reward, terminated, truncated, info


def _flat(observation: Any) -> np.ndarray:
    return np.asarray(observation, dtype=np.float32).reshape(-1)


def make_user_env(env_id: str, render_mode: str | None = None) -> gym.Env[Any, Any]:
    """``gymnasium.make(env_id)``, importing its module from the current directory too; each way it can fail
    is an ``UnusableEnvironment`` whose one line says what to add."""
    module, _, name = env_id.partition(":")
    if not module or not name:
        raise UnusableEnvironment(f"--env {env_id!r}: expected module:EnvId, e.g. my_package.envs:MyTask-v0")
    if os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())
    try:
        return gym.make(env_id, render_mode=render_mode)
    except ModuleNotFoundError as error:
        cause = error.__cause__ or error
        raise UnusableEnvironment(
            f"--env {env_id}: cannot import {module} ({cause}); run from the folder that holds it, or add that "
            "folder to PYTHONPATH"
        ) from None
    except gym.error.Error as error:
        raise UnusableEnvironment(
            f"--env {env_id}: importing {module} registers no {name} ({error}); add "
            f"gymnasium.register(id={name!r}, entry_point=...) to {module}"
        ) from None
    except Exception as error:
        raise UnusableEnvironment(f"--env {env_id}: making it failed: {type(error).__name__}: {error}") from None


def declared_task_space(env: gym.Env[Any, Any], env_id: str) -> TaskSpace:
    """The task space the unwrapped environment declares, checked as the service's registration checks it."""
    raw = getattr(env.unwrapped, TASK_SPACE_ATTRIBUTE, None)
    if raw is None:
        raise UnusableEnvironment(
            f"--env {env_id}: the environment has no {TASK_SPACE_ATTRIBUTE} attribute; add one, a list of "
            'parameters such as [{"name": "difficulty", "low": 0.0, "high": 1.0}] (docs/own-environment.md)'
        )
    try:
        return CurriculumSpecBase.model_validate({"space": raw}).task_space()
    except (ValidationError, ValueError) as error:
        problem = " ".join(str(error).split())
        raise UnusableEnvironment(
            f"--env {env_id}: its {TASK_SPACE_ATTRIBUTE} is not a valid task space: {problem}"
        ) from None


@functools.cache
def _described(env_id: str) -> tuple[TaskSpace, PolicyShape]:
    """The environment's task space and policy shape, read once per process from one made environment."""
    env = make_user_env(env_id)
    try:
        shape = shape_of_spaces(env.observation_space, env.action_space)
        return declared_task_space(env, env_id), shape
    except UnusableEnvironment as error:
        raise UnusableEnvironment(
            str(error) if str(error).startswith("--env") else f"--env {env_id}: {error}"
        ) from None
    finally:
        env.close()  # type: ignore[no-untyped-call]  # gymnasium's Env.close is unannotated


class GymnasiumFamily(TaskFamily):
    """Every ``module:EnvId`` environment; the others' ids hold no colon."""

    name = "gymnasium module:EnvId"

    def owns(self, env_id: str) -> bool:
        return ":" in env_id

    def check(self, env_id: str) -> None:
        _described(env_id)

    def make_env(
        self,
        env_id: str,
        max_steps: int,
        render_mode: str | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> gym.Env[np.ndarray, Any]:
        return TaskEnvironment(make_user_env(env_id, render_mode=render_mode), max_steps)

    def task_space(self, env_id: str, levels: int) -> TaskSpace:
        return _described(env_id)[0]

    def policy_shape(self, env_id: str) -> PolicyShape:
        return _described(env_id)[1]
