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
    """Every task uniform over the space: the baseline a curriculum has to beat (over levels, each
    level equally likely)."""

    kind = "random"
    parameter_types = frozenset({"float", "integer"})
    Params = RandomParams
    params: RandomParams

    def __init__(self, space: TaskSpace, seed: int, params: RandomParams | Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed, params)

    def _draw(self, first_index: int, count: int) -> list[Task]:
        unit = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, len(self.space))
        values = self.space.from_unit(unit)
        whole = self.space.integer
        if whole.any():
            # Each of an integer parameter's high - low + 1 values takes an equal share of [0, 1).
            levels = self.space.high[whole] - self.space.low[whole] + 1
            values[:, whole] = self.space.low[whole] + np.floor(unit[:, whole] * levels)
        return [self.space.from_array(row) for row in values]

    def _learn_validated(self, result: EpisodeResult) -> FitJob | None:
        return None

    def _describe(self) -> dict[str, Any]:
        return {}


class FixedParams(TeacherParams):
    point: TaskParam | None = None
    """The one task to train on; null means the space's hardest point (the evaluation setting)."""


class FixedTeacher(Teacher):
    """Always the same task: training without a curriculum."""

    kind = "fixed"
    parameter_types = frozenset({"float", "integer"})
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
