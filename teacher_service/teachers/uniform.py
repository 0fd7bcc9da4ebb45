"""The two baselines: uniform sampling over the whole box, and one fixed task ("no curriculum")."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.task_space import Task, TaskSpace
from teacher_service.teachers.base import EpisodeResult, FitJob, Teacher
from teacher_service.teachers.draws import TASK_STREAM, indexed_uniforms
from teacher_service.teachers.params import as_task, in_space, parse_params, store


@dataclass(frozen=True)
class RandomParams:
    """Uniform sampling has no parameters."""


class RandomTeacher(Teacher):
    """Every task uniform over the box: the baseline a curriculum has to beat."""

    kind = "random"

    def __init__(self, space: TaskSpace, seed: int, params: Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed)
        self.params = parse_params(self.kind, RandomParams, params)

    def _draw(self, first_index: int, count: int) -> list[Task]:
        unit = indexed_uniforms(self.seed, TASK_STREAM, first_index, count, len(self.space))
        return [self.space.from_array(row) for row in self.space.from_unit(unit)]

    def _learn(self, result: EpisodeResult) -> FitJob | None:
        return None

    def _describe(self) -> dict[str, Any]:
        return {}

    def _export(self) -> dict[str, Any]:
        return {}

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        """Nothing beyond the counters: task ``i`` depends on the seed and ``i`` only."""


@dataclass(frozen=True)
class FixedParams:
    point: Task | None = None
    """The one task to train on; None means the space's hardest point (the evaluation setting)."""

    def __post_init__(self) -> None:
        store(self, point=as_task("point", self.point))


class FixedTeacher(Teacher):
    """Always the same task: training without a curriculum."""

    kind = "fixed"

    def __init__(self, space: TaskSpace, seed: int, params: Mapping[str, Any] | None = None) -> None:
        super().__init__(space, seed)
        self.params = parse_params(self.kind, FixedParams, params)
        if self.params.point is not None:
            self.point = in_space("point", self.params.point, space)
        else:
            try:
                self.point = space.hardest()
            except ValueError as error:
                raise ValueError(f"point: none given and {error}") from None

    def _draw(self, first_index: int, count: int) -> list[Task]:
        return [dict(self.point) for _ in range(count)]

    def _learn(self, result: EpisodeResult) -> FitJob | None:
        return None

    def _describe(self) -> dict[str, Any]:
        return {"point": dict(self.point)}

    def _export(self) -> dict[str, Any]:
        return {}

    def _import(self, state: Mapping[str, Any], history: np.ndarray) -> None:
        """Nothing beyond the counters: the task never changes."""
