"""The base of every teacher kind's parameters: a typed, bounded pydantic model.

Each kind declares its parameters as a ``TeacherParams`` subclass with a bound on every number, so
that one request cannot make the teacher cost more than those bounds allow (memory, the number of
lessons, the work of one fit). The service puts these models in its request schema, which makes
``/docs`` show each field's bounds, default and doc, and turns a bad value into a 422 naming it.
Checks that need the task space (a task-valued parameter lying inside it) run in the teacher.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from typing_extensions import Self

from common.client.schemas import FiniteFloat
from common.client.task_space import Task, TaskSpace

TaskParam = Annotated[
    dict[Annotated[str, Field(max_length=64)], int | FiniteFloat],
    Field(max_length=64, description="A task: parameter name to value, inside the curriculum's space."),
]
"""A task-valued parameter; ``in_space`` checks it against the teacher's space."""

TaskRange = Annotated[list[FiniteFloat], Field(min_length=2, max_length=2)]
"""A [low, high] pair of task values."""

TaskBox = Annotated[
    dict[Annotated[str, Field(max_length=64)], TaskRange],
    Field(
        min_length=1,
        max_length=64,
        description="A box of tasks: parameter name to [low, high] inside the curriculum's space; "
        "a parameter not named sits at its hardest value.",
    ),
]
"""A box-valued parameter; ``box_in_space`` checks it against the teacher's space."""

__all__ = [
    "FiniteFloat",
    "TaskBox",
    "TaskParam",
    "TeacherParams",
    "box_in_space",
    "check_target_box",
    "given_or_anchor",
    "in_space",
]


class TeacherParams(BaseModel):
    """Immutable, unknown names refused, no type coercion (``true`` is not 1, ``"7"`` is not 7)."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, use_attribute_docstrings=True)

    @classmethod
    def parse(cls, raw: TeacherParams | Mapping[str, Any] | None) -> Self:
        """The parameters from a model of this kind, a mapping of name to value, or ``None`` (defaults).

        Raises ``pydantic.ValidationError`` (a ``ValueError``) naming each bad field."""
        if raw is None:
            return cls()
        if isinstance(raw, cls):
            return raw
        if isinstance(raw, Mapping):
            return cls.model_validate(dict(raw))
        raise ValueError(f"parameters must be a mapping of name to value, got {type(raw).__name__}")


def given_or_anchor(name: str, given: Task | None, space: TaskSpace, anchor: Literal["easiest", "hardest"]) -> Task:
    """A task-valued parameter checked against the space, or when none was given the space's
    ``anchor`` point; either failure names the parameter."""
    if given is not None:
        return in_space(name, given, space)
    try:
        return space.easiest() if anchor == "easiest" else space.hardest()
    except ValueError as error:
        raise ValueError(f"{name}: none given and {error}") from None


def in_space(name: str, task: Task, space: TaskSpace) -> Task:
    """Validate a task-valued parameter against the teacher's space, naming the parameter."""
    try:
        return space.validate(task)
    except ValueError as error:
        raise ValueError(f"{name}: {error}") from None


def check_target_box(target: str, target_box: Mapping[str, Sequence[float]] | None) -> None:
    """``target`` = box needs a ``target_box``, and a ``target_box`` needs ``target`` = box."""
    if target == "box" and target_box is None:
        raise ValueError("target 'box' needs a target_box: parameter name to [low, high]")
    if target != "box" and target_box is not None:
        raise ValueError(f"target_box is read only with target 'box', not {target!r}")


def box_in_space(name: str, box: Mapping[str, Sequence[float]], space: TaskSpace) -> tuple[np.ndarray, np.ndarray]:
    """A box-valued parameter checked against the space: its low and high corners in unit
    coordinates, each parameter it does not name at the space's hardest value; a failure names the
    parameter."""
    unknown = sorted(set(box) - set(space.names))
    if unknown:
        raise ValueError(f"{name}: unknown task parameter(s) {unknown}; expected {list(space.names)}")
    corners = np.empty((2, len(space)))
    for column, p in enumerate(space.parameters):
        if p.name in box:
            low, high = box[p.name]
            if low > high:
                raise ValueError(f"{name}: {p.name!r} needs low <= high, got [{low}, {high}]")
            if low < p.low or high > p.high:
                raise ValueError(f"{name}: {p.name!r} range [{low}, {high}] is outside its bounds [{p.low}, {p.high}]")
        elif p.hardest is None:
            raise ValueError(f"{name}: {p.name!r} is not given and this task space defines no hardest value for it")
        else:
            low = high = p.hardest
        corners[:, column] = low, high
    unit: np.ndarray = space.to_unit(corners)
    return unit[0], unit[1]
