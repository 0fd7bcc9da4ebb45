"""The KUKA grasp families (``KukaGrasp-v0``, ``KukaGraspHard-v0`` and ``-v1``): pybullet loads only when an
environment is made."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from common.client.task_space import Task, TaskSpace
from common.families.base import Controller, EvaluationSeeds, PlayedEpisode, PolicyShape, TaskFamily
from common.kuka import ENV_IDS, HARD_ENV_ID, HARD_V1_ENV_ID
from common.kuka.task_space import task_space_for
from common.policy.inference import WorldOffset

KUKA_TEACHER_PARAMS: dict[str, dict[str, Any]] = {
    "alp-gmm": {"reward_range": [-5.0, 10.0], "target_task_ratio": 0.2},
    "adr": {"reward_range": [0.0, 10.0]},
    "self-paced": {"reward_range": [0.0, 10.0]},
    "manual": {"metric": "reward", "threshold": 5.5},
    "currot": {"delta": 5.0, "estimate": "recent"},
}
"""Teacher parameters for the KUKA curriculum, on top of each teacher's own defaults. ALP-GMM
clusters learning progress together with task coordinates rescaled to [0, 1], so the scaled return
(about -3 for a miss, about +9 for a grasp) is mapped onto [0, 1] too, and a fifth of its tasks are
the hardest task, which its other tasks rarely reach in the outer part of the test's range. ADR and
self-paced map a KUKA return onto [0, 1] by [0, 10] (a grasp pays about +10) when a result carries no
success, the lesson plan moves on at the book's mean reward of 5.5, and CURROT holds a return to 5
(half a grasp) and estimates from its recent results rather than its authors' lasting success
buffer. Why each, with the runs that chose them: docs/results/bakeoff-v0.md and
docs/results/bakeoff-hard.md."""

EDGE_PLACEMENT_SHARE = "edge_placement_share"
"""The hard families' training-only option: the share of far training placements drawn beyond the arm's x
clamp (``KukaGraspHardEnv``); evaluations keep the task's own draw."""


def kuka_teacher_params(teacher: str, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """What a KUKA curriculum is registered with: ``KUKA_TEACHER_PARAMS``, then the overrides. The
    training CLI and the examples share it, so one teacher name means one configuration everywhere."""
    return {**KUKA_TEACHER_PARAMS.get(teacher, {}), **overrides}


class KukaFamily(TaskFamily):
    """The arm over a block: a six- or ten-parameter box, evaluated deterministically on its hardest point."""

    name = "KUKA grasp"
    options = (EDGE_PLACEMENT_SHARE,)

    def owns(self, env_id: str) -> bool:
        return env_id in ENV_IDS

    def env_ids(self) -> tuple[str, ...]:
        return ENV_IDS

    def make_env(
        self,
        env_id: str,
        max_steps: int,
        render_mode: str | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> gym.Env[np.ndarray, Any]:
        from common.kuka.env import make_kuka_env  # here: the environment module loads pybullet

        extra = {name: value for name, value in (options or {}).items() if value}
        return make_kuka_env(env_id, max_steps=max_steps, render_mode=render_mode, **extra)

    def check_options(self, env_id: str, options: Mapping[str, Any]) -> None:
        super().check_options(env_id, options)
        if options.get(EDGE_PLACEMENT_SHARE) and env_id not in (HARD_ENV_ID, HARD_V1_ENV_ID):
            raise ValueError(
                f"{EDGE_PLACEMENT_SHARE} needs a hard KUKA family ({HARD_ENV_ID} or {HARD_V1_ENV_ID}), not {env_id}"
            )

    def task_space(self, env_id: str, levels: int) -> TaskSpace:
        return task_space_for(env_id)

    def evaluation_task(self, env_id: str, levels: int) -> Task:
        """The hardest task of the family; for ``KukaGrasp-v0`` the book's evaluation setting."""
        return task_space_for(env_id).hardest()

    def evaluation_seeds(self, env_id: str, levels: int, episodes: int, scheme: EvaluationSeeds) -> list[int]:
        """``scheme``'s seeds (``common.kuka.evaluation_seeds``): consecutive from 10,000, or stratified by
        where their blocks lie."""
        from common.kuka.evaluation_seeds import stratified_seeds  # here: it plays the family's placements

        if scheme == "stratified":
            return list(stratified_seeds(env_id, episodes))
        return super().evaluation_seeds(env_id, levels, episodes, scheme)

    def check_evaluation(self, env_id: str, episodes: int, scheme: EvaluationSeeds) -> None:
        from common.kuka.evaluation_seeds import MAX_STRATIFIED_EPISODES

        if scheme == "stratified" and episodes > MAX_STRATIFIED_EPISODES:
            raise ValueError(f"stratified evaluation seeds take at most {MAX_STRATIFIED_EPISODES:,} eval_episodes")

    def play_episode(self, env: gym.Env[np.ndarray, Any], task: Task, act: Controller, seed: int) -> PlayedEpisode:
        """The episode with where its block lay and how the gripper met it (``common.kuka.diagnostics``)."""
        from common.kuka.diagnostics import play_episode  # here: the diagnostics module loads pybullet
        from common.kuka.env import KukaGraspEnv

        assert isinstance(env, KukaGraspEnv), "make_env gives the bare KUKA environment"
        episode = play_episode(env, task, act, seed)
        return PlayedEpisode(episode.reward, episode.success, episode.length, episode.diagnostics)

    def scripted_controller(self, env_id: str) -> Controller:
        """The controller that turns the wrist to the block and aligns over it (``common.kuka.scripted``)."""
        from common.kuka.scripted import scripted_action

        return scripted_action

    def policy_shape(self, env_id: str) -> PolicyShape:
        from common.kuka.env import (  # here: the environment module loads pybullet
            BLOCK_XY_IN_GRIPPER,
            BLOCK_YAW_INDEX,
            GRIPPER_EULER_INDICES,
            KukaGraspEnv,
        )

        probe = KukaGraspEnv()
        try:
            observation_shape, action_shape = probe.observation_space.shape, probe.action_space.shape
            return PolicyShape(
                observation_dim=observation_shape[0],
                action_dim=action_shape[0],
                angle_indices=probe.angle_indices,
                world_offset=WorldOffset(
                    BLOCK_XY_IN_GRIPPER.start, BLOCK_XY_IN_GRIPPER.start + 1, GRIPPER_EULER_INDICES
                ),
                half_turn_indices=(BLOCK_YAW_INDEX,),
            )
        finally:
            probe.close()

    def teacher_params(self, teacher: str, overrides: Mapping[str, Any]) -> dict[str, Any]:
        return kuka_teacher_params(teacher, overrides)
