"""The two baselines: uniform sampling over the whole box, and one fixed task ("no curriculum")."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from common.client.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms
from teacher_service.teachers.params import TaskParam, TeacherParams, given_or_anchor


class RandomParams(TeacherParams):
    """Uniform sampling has no parameters."""


class RandomTeacher(Teacher):
    """Every task uniform over the box: the baseline a curriculum has to beat."""

    kind = "random"
    Params = RandomParams
    params: RandomParams

    def __init__(self, space: TaskSpace, seed: int, params: RandomParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)

    def _draw(self, first_index: int, count: int) -> list[Task]:
        unit = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, len(self.space))
        return [self.space.from_array(row) for row in self.space.from_unit(unit)]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        return None

    def _describe(self) -> dict[str, Any]:
        return {}

    def _export(self) -> dict[str, Any]:
        return {}

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        """Nothing beyond the counters: task ``i`` depends on the seed and ``i`` only."""


class FixedParams(TeacherParams):
    point: TaskParam | None = None
    """The one task to train on; null means the space's hardest point (the evaluation setting)."""


class FixedTeacher(Teacher):
    """Always the same task: training without a curriculum."""

    kind = "fixed"
    Params = FixedParams
    params: FixedParams

    def __init__(self, space: TaskSpace, seed: int, params: FixedParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)
        self.point = given_or_anchor("point", self.params.point, space, "hardest")

    def _draw(self, first_index: int, count: int) -> list[Task]:
        return [dict(self.point) for _ in range(count)]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        return None

    def _describe(self) -> dict[str, Any]:
        return {"point": dict(self.point)}

    def _export(self) -> dict[str, Any]:
        return {}

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        """Nothing beyond the counters: the task never changes."""
