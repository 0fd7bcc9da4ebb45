"""What a task family is: everything the trainer, its rollout workers and its evaluations need to know of an
environment, in one object, so that none of them asks which family a run is on.

A family owns a set of environment ids. For each it makes the bare environment the workers step (its
observation flat ``float32``, its success ``info["is_success"]`` at an episode's end, its task from
``reset(options={"task": ...})``), names its task space and its evaluation (the task, the seeds, whether the
policy acts deterministically), gives the policy's shape (how observations are encoded, which head acts)
and the teacher parameters a curriculum over it is registered with. ``common.families`` lists the families.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import gymnasium as gym
import numpy as np

from common.client.task_space import Task, TaskSpace
from common.policy.inference import MIN_IMAGE_SIDE, WorldOffset

EvaluationSeeds = Literal["consecutive", "stratified"]
EVALUATION_SEED_SCHEMES: tuple[EvaluationSeeds, ...] = ("consecutive", "stratified")
EVALUATION_SEED_OFFSET = 10_000
"""Consecutive evaluation seeds are EVALUATION_SEED_OFFSET + 0, 1, 2, ...: apart from ``evaluate``'s seeds
from 0 and from a bake-off's final evaluation's from 100,000."""

HELD_OUT_FIRST_SEED = 1_000_000
"""Held-out levels are the reset seeds from here up, outside any training set of at most ``MAX_LEVELS``."""


Controller = Callable[[np.ndarray], np.ndarray]
"""Observation to action (a Box's vector, or a Discrete choice's index as a one-entry array)."""


@dataclass(frozen=True)
class PlayedEpisode:
    """One evaluation episode's figures, and what its family records of it (KUKA's placement and touchdown)."""

    reward: float
    success: bool
    length: int
    diagnostics: object | None = None


def env_action(space: gym.Space[Any], action: np.ndarray) -> Any:
    """One policy action as ``env.step`` takes it: a ``Discrete`` choice's index (carried as a one-entry array) as
    an int, a ``Box`` vector clipped into the box, as the rollout workers clip it."""
    if isinstance(space, gym.spaces.Discrete):
        return int(action[0])
    assert isinstance(space, gym.spaces.Box), "a family's actions are Discrete or a Box"
    return np.clip(action, space.low, space.high)


class UnusableEnvironment(ValueError):
    """An environment the trainer cannot train on; the message is one line that says what to add or fix."""


@dataclass(frozen=True)
class PolicyShape:
    """The policy's shape on a family's environment: how observations are encoded and which head acts.

    Observations reach the policy flat; an image's ``image_shape`` (height, width, channels) says how to fold
    them back for a CNN. A ``Discrete`` action space gets a categorical head over ``action_dim`` choices, a
    ``Box`` a Gaussian over ``action_dim`` dimensions. The other fields are a family's own features, which the
    learner's ``PPOConfig`` switches on (KUKA's angles, the block's offset and its half-turn yaw)."""

    observation_dim: int
    action_dim: int
    categorical: bool = False
    image_shape: tuple[int, int, int] | None = None
    angle_indices: tuple[int, ...] = ()
    world_offset: WorldOffset | None = None
    half_turn_indices: tuple[int, ...] = ()


def shape_of_spaces(observation_space: gym.Space[Any], action_space: gym.Space[Any]) -> PolicyShape:
    """A plain environment's policy shape: a flat ``Box`` observation an MLP's input, an image ``Box``
    (height x width x channels, ``uint8``) a CNN's; a ``Discrete`` action a categorical head, a ``Box`` a
    Gaussian. Anything else is an ``UnusableEnvironment``."""
    if not isinstance(observation_space, gym.spaces.Box) or observation_space.shape is None:
        raise UnusableEnvironment(f"the observation space must be a Box, got {observation_space}")
    shape = tuple(int(size) for size in observation_space.shape)
    image_shape: tuple[int, int, int] | None = None
    if len(shape) == 3 and observation_space.dtype == np.uint8:
        image_shape = (shape[0], shape[1], shape[2])
        if min(image_shape[:2]) < MIN_IMAGE_SIDE:
            raise UnusableEnvironment(
                f"an image observation needs sides of {MIN_IMAGE_SIDE} pixels or more, got {shape}"
            )
    elif len(shape) != 1:
        raise UnusableEnvironment(
            f"the observation must be a flat Box or an image Box (height x width x channels, uint8), got {shape} "
            f"{observation_space.dtype}"
        )
    if isinstance(action_space, gym.spaces.Discrete):
        if int(action_space.n) < 2:
            raise UnusableEnvironment(f"a Discrete action space needs at least 2 actions, got {action_space}")
        return PolicyShape(int(np.prod(shape)), int(action_space.n), categorical=True, image_shape=image_shape)
    if isinstance(action_space, gym.spaces.Box) and action_space.shape is not None and len(action_space.shape) == 1:
        return PolicyShape(int(np.prod(shape)), int(action_space.shape[0]), image_shape=image_shape)
    raise UnusableEnvironment(f"the action space must be Discrete or a flat Box, got {action_space}")


def held_out_seeds(episodes: int, first: int = 0) -> list[int]:
    """The reset seeds of ``episodes`` held-out levels from the ``first``-th on, the same in every evaluation."""
    return [HELD_OUT_FIRST_SEED + first + index for index in range(episodes)]


def is_level_space(space: TaskSpace) -> bool:
    """A space of integer parameters alone: its tasks are levels, and it is evaluated on held-out levels
    (an environment reset with no task, its seed outside the training set), not on a hardest task."""
    return space.types == frozenset({"integer"})


class TaskFamily(ABC):
    """One kind of environment the trainer can teach; ``common.families`` holds one instance of each."""

    name: ClassVar[str]
    """How people call the family, in messages and docs."""
    deterministic_evaluation: ClassVar[bool] = True
    """Evaluations play the policy's likeliest action (a Gaussian's mean); False: they sample it."""
    options: ClassVar[tuple[str, ...]] = ()
    """The training-only options its ``make_env`` takes (``TrainConfig``'s family options)."""

    @abstractmethod
    def owns(self, env_id: str) -> bool:
        """Whether ``env_id`` is one of this family's environments."""

    def env_ids(self) -> tuple[str, ...]:
        """The ids to list in ``train --env``'s help (none for a family that takes any id)."""
        return ()

    def check(self, env_id: str) -> None:  # noqa: B027  # a family whose ids are all listed has nothing to check
        """Raise ``UnusableEnvironment`` when ``env_id`` cannot be trained on; nothing otherwise."""

    @abstractmethod
    def make_env(
        self,
        env_id: str,
        max_steps: int,
        render_mode: str | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> gym.Env[np.ndarray, Any]:
        """The bare environment the workers step, cut at ``max_steps``; ``options`` are training-only ones."""

    @abstractmethod
    def task_space(self, env_id: str, levels: int) -> TaskSpace:
        """The space the teacher draws tasks from; ``levels`` sizes a family whose levels are reset seeds."""

    def evaluation_task(self, env_id: str, levels: int) -> Task:
        """The task evaluations play: the space's hardest, or none on a level space (held-out levels)."""
        space = self.task_space(env_id, levels)
        return {} if is_level_space(space) else space.hardest()

    def evaluation_seeds(self, env_id: str, levels: int, episodes: int, scheme: EvaluationSeeds) -> list[int]:
        """The seeds of a run's in-run evaluation episodes, fixed for the whole run."""
        if is_level_space(self.task_space(env_id, levels)):
            return held_out_seeds(episodes)
        return [EVALUATION_SEED_OFFSET + index for index in range(episodes)]

    def check_evaluation(self, env_id: str, episodes: int, scheme: EvaluationSeeds) -> None:  # noqa: B027  # most take any
        """Raise ``ValueError`` for in-run evaluation settings this family cannot play."""

    def episode_seeds(self, env_id: str, levels: int, first: int, episodes: int) -> list[int]:
        """The seeds of ``evaluate``'s and ``render``'s episodes from ``--seed first``: consecutive, on a level
        space the held-out levels' (a seed is a level there, and seeds from 0 are training levels)."""
        if is_level_space(self.task_space(env_id, levels)):
            return held_out_seeds(episodes, first)
        return [first + index for index in range(episodes)]

    def play_episode(self, env: gym.Env[np.ndarray, Any], task: Task, act: Controller, seed: int) -> PlayedEpisode:
        """One whole episode of ``act`` on ``task`` (none: the environment's own draw from ``seed``), its actions
        clipped into a Box as the rollout workers clip them."""
        observation, info = env.reset(seed=seed, options={"task": task})
        total, length, done = 0.0, 0, False
        while not done:
            observation, reward, terminated, truncated, info = env.step(env_action(env.action_space, act(observation)))
            total += float(reward)
            length += 1
            done = terminated or truncated
        return PlayedEpisode(total, bool(info.get("is_success", False)), length)

    def scripted_controller(self, env_id: str) -> Controller:
        """A hand-made controller to read a policy against; ``UnusableEnvironment`` where the family has none."""
        raise UnusableEnvironment(f"{env_id} ({self.name}) has no scripted controller; evaluate a checkpoint")

    @abstractmethod
    def policy_shape(self, env_id: str) -> PolicyShape:
        """The policy's shape on this environment."""

    def teacher_params(self, teacher: str, overrides: Mapping[str, Any]) -> dict[str, Any]:
        """The parameters a curriculum over this family is registered with: the overrides, on the teacher
        kind's own defaults, unless the family has better ones."""
        return dict(overrides)

    def check_options(self, env_id: str, options: Mapping[str, Any]) -> None:
        """Raise ``ValueError`` for a training option this family or environment does not take."""
        unknown = sorted(name for name, value in options.items() if value and name not in self.options)
        if unknown:
            raise ValueError(f"{', '.join(unknown)} do not apply to {env_id} ({self.name})")
