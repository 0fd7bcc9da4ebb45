"""Checks for teacher parameters arriving as untrusted JSON-like data.

Each kind declares its parameters as a frozen dataclass whose ``__post_init__`` cleans its fields
with the helpers below; every error names the parameter so an HTTP layer can pass it on verbatim.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

from common.task_space import Task, TaskSpace

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

Params = TypeVar("Params", bound="DataclassInstance")


def parse_params(kind: str, schema: type[Params], raw: Mapping[str, Any] | None) -> Params:
    """Build ``schema`` from ``raw``, rejecting names it does not declare."""
    if raw is None:
        raw = {}
    if not isinstance(raw, Mapping):
        raise ValueError(f"{kind} parameters must be a mapping of name to value, got {type(raw).__name__}")
    known = [field.name for field in dataclasses.fields(schema)]
    unknown = sorted(set(raw) - set(known))
    if unknown:
        raise ValueError(f"unknown {kind} parameter(s) {unknown}; known: {known}")
    return schema(**raw)


def store(params: Any, **cleaned: Any) -> None:
    """Write cleaned values onto a frozen dataclass from its ``__post_init__``."""
    for name, value in cleaned.items():
        object.__setattr__(params, name, value)


def as_int(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be at least {minimum}, got {value}")
    return int(value)


def as_float(name: str, value: Any, low: float = -math.inf, high: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if not low <= value <= high:
        raise ValueError(f"{name} must lie in [{low}, {high}], got {value}")
    return float(value)


def as_bool(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return value


def as_range(name: str, value: Any) -> list[float] | None:
    """``None`` or ``[low, high]`` with low < high."""
    if value is None:
        return None
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 2:
        raise ValueError(f"{name} must be null or a pair [low, high], got {value!r}")
    low, high = (as_float(f"{name}[{i}]", v) for i, v in enumerate(value))
    if not low < high:
        raise ValueError(f"{name} must have low < high, got [{low}, {high}]")
    return [low, high]


def as_task(name: str, value: Any) -> Task | None:
    """``None`` or a mapping of parameter name to number; checked against a space by ``in_space``."""
    if value is None:
        return None
    if not isinstance(value, Mapping):
        raise ValueError(f"{name} must be null or a task (parameter name to value), got {value!r}")
    return {str(key): as_float(f"{name}.{key}", v) for key, v in value.items()}


def in_space(name: str, task: Task, space: TaskSpace) -> Task:
    """Validate a task-valued parameter against the teacher's space, naming the parameter."""
    try:
        return space.validate(task)
    except ValueError as error:
        raise ValueError(f"{name}: {error}") from None
