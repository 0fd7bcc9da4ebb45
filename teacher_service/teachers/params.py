"""The base of every teacher kind's parameters: a typed, bounded pydantic model.

Each kind declares its parameters as a ``TeacherParams`` subclass with a bound on every number, so
that one request cannot make the teacher cost more than those bounds allow (memory, the number of
lessons, the work of one fit). The service puts these models in its request schema, which makes
``/docs`` show each field's bounds, default and doc, and turns a bad value into a 422 naming it.
Checks that need the task space (a task-valued parameter lying inside it) run in the teacher.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field
from typing_extensions import Self

from common.client.schemas import FiniteFloat
from common.client.task_space import Task, TaskSpace

TaskParam = Annotated[
    dict[Annotated[str, Field(max_length=64)], FiniteFloat],
    Field(max_length=64, description="A task: parameter name to value, inside the curriculum's space."),
]
"""A task-valued parameter; ``in_space`` checks it against the teacher's space."""

__all__ = ["FiniteFloat", "TaskParam", "TeacherParams", "given_or_anchor", "in_space"]


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
