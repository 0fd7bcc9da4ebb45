"""The curriculum task space: named, bounded parameters that set an episode's difficulty.

A task is a plain ``dict`` of parameter name to value: a float for a float parameter (a box's side),
an int for an integer one (a level seed, a layout choice; ``low`` and ``high`` both included). One
integer parameter is gymnasium's Discrete(n), several are MultiDiscrete. ``TaskSpace`` is generic:
the teacher service builds spaces from HTTP requests, a trainer declares its own (the KUKA spaces
are in ``common.kuka.task_space``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

Task = dict[str, float]
"""Parameter name to value; an integer parameter's value is an ``int`` (which a float annotation admits)."""

ParameterType = Literal["float", "integer"]
PARAMETER_TYPES: tuple[ParameterType, ...] = ("float", "integer")
MAX_LEVELS = 10_000
"""The most levels (value combinations) of an integer space that the service's level kinds track: SFL's held-out
set, above Procgen's 200 training levels. Each level costs a kind a few array entries (a draw a few passes over
them, a snapshot about 25 bytes a level), so a larger space is a 422. Trainers size their level sets by it too."""


@dataclass(frozen=True)
class Parameter:
    """One task dimension. ``easiest``/``hardest`` are optional anchors used by curricula.

    An ``integer`` parameter takes the whole numbers from ``low`` to ``high`` inclusive; its bounds
    and anchors must be whole numbers, and are kept as ``int``."""

    name: str
    low: float
    high: float
    hardest: float | None = None
    easiest: float | None = None
    doc: str = ""
    type: ParameterType = "float"

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("parameter name must be non-empty")
        if self.type not in PARAMETER_TYPES:
            raise ValueError(f"parameter {self.name!r}: type must be one of {list(PARAMETER_TYPES)}, got {self.type!r}")
        if not (math.isfinite(self.low) and math.isfinite(self.high)) or self.low > self.high:
            raise ValueError(f"parameter {self.name!r}: need finite low <= high, got [{self.low}, {self.high}]")
        for label, value in (("hardest", self.hardest), ("easiest", self.easiest)):
            if value is not None and not self.low <= value <= self.high:
                raise ValueError(f"parameter {self.name!r}: {label}={value} outside [{self.low}, {self.high}]")
        if self.type == "integer":
            for label in ("low", "high", "hardest", "easiest"):
                value = getattr(self, label)
                if value is not None and not float(value).is_integer():
                    raise ValueError(f"parameter {self.name!r} is an integer parameter: {label}={value} is not whole")
                if value is not None:
                    object.__setattr__(self, label, int(value))

    @property
    def levels(self) -> int:
        """How many values an integer parameter takes (``high - low + 1``)."""
        if self.type != "integer":
            raise ValueError(f"parameter {self.name!r} is a float parameter: it has no count of levels")
        return int(self.high - self.low) + 1


class TaskSpace:
    """An ordered box of parameters with validation and array conversion."""

    def __init__(self, parameters: Iterable[Parameter]) -> None:
        self.parameters: tuple[Parameter, ...] = tuple(parameters)
        if not self.parameters:
            raise ValueError("a task space needs at least one parameter")
        self.names: tuple[str, ...] = tuple(p.name for p in self.parameters)
        if len(set(self.names)) != len(self.names):
            raise ValueError(f"duplicate parameter names in {self.names}")
        self.low = np.array([p.low for p in self.parameters], dtype=np.float64)
        self.high = np.array([p.high for p in self.parameters], dtype=np.float64)
        self.integer = np.array([p.type == "integer" for p in self.parameters])
        """Which dimensions are integer parameters."""

    @property
    def types(self) -> frozenset[ParameterType]:
        """The parameter types this space uses."""
        return frozenset(p.type for p in self.parameters)

    def level_count(self) -> int:
        """How many distinct tasks an all-integer space holds: the product of its parameters' levels
        (Python's int, so a huge MultiDiscrete space does not overflow)."""
        return math.prod(p.levels for p in self.parameters)

    def level_task(self, level: int) -> Task:
        """The task numbered ``level`` in an all-integer space, the first parameter varying slowest."""
        if not 0 <= level < self.level_count():
            raise ValueError(f"level {level} is outside [0, {self.level_count() - 1}]")
        task: Task = {}
        for parameter in reversed(self.parameters):
            level, offset = divmod(level, parameter.levels)
            task[parameter.name] = int(parameter.low) + offset
        return {name: task[name] for name in self.names}

    def task_level(self, task: Mapping[str, float]) -> int:
        """The number of a valid task of an all-integer space: ``level_task``'s inverse."""
        level = 0
        for parameter in self.parameters:
            level = level * parameter.levels + int(task[parameter.name] - parameter.low)
        return level

    def __len__(self) -> int:
        return len(self.parameters)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, TaskSpace) and self.parameters == other.parameters

    def __hash__(self) -> int:
        return hash(self.parameters)

    def __repr__(self) -> str:
        return f"TaskSpace({', '.join(f'{p.name}=[{p.low}, {p.high}]' for p in self.parameters)})"

    def validate(self, task: Mapping[str, float]) -> Task:
        """Return a clean copy of ``task`` or raise ``ValueError`` naming the offending parameter."""
        if not isinstance(task, Mapping):
            raise ValueError(f"a task must be a mapping of parameter name to value, got {type(task).__name__}")
        unknown = sorted(set(task) - set(self.names))
        if unknown:
            raise ValueError(f"unknown task parameter(s) {unknown}; expected {list(self.names)}")
        missing = [name for name in self.names if name not in task]
        if missing:
            raise ValueError(f"missing task parameter(s) {missing}")
        clean: Task = {}
        for p in self.parameters:
            raw = task[p.name]
            if p.type == "integer":
                clean[p.name] = _whole_number(p, raw)
                continue
            try:
                value = float(raw)
            except (TypeError, ValueError):
                raise ValueError(f"task parameter {p.name!r} must be a number, got {raw!r}") from None
            if not math.isfinite(value):
                raise ValueError(f"task parameter {p.name!r} must be finite, got {value}")
            if not p.low <= value <= p.high:
                raise ValueError(f"task parameter {p.name!r}={value} is outside its bounds [{p.low}, {p.high}]")
            clean[p.name] = value
        return clean

    def to_array(self, task: Mapping[str, float]) -> np.ndarray:
        return np.array([task[name] for name in self.names], dtype=np.float64)

    def from_array(self, values: np.ndarray) -> Task:
        """Map a vector to a task, clipping into the box (sampling noise can step outside) and
        rounding integer parameters to the nearest whole number."""
        clipped = np.clip(np.asarray(values, dtype=np.float64), self.low, self.high)
        return {
            name: int(np.rint(v)) if whole else float(v)
            for name, v, whole in zip(self.names, clipped, self.integer, strict=True)
        }

    def to_unit(self, points: np.ndarray) -> np.ndarray:
        """Rescale points (n, d) to [0, 1] per dimension; a zero-width dimension maps to 0."""
        width = np.where(self.high > self.low, self.high - self.low, 1.0)
        return (np.asarray(points, dtype=np.float64) - self.low) / width

    def from_unit(self, points: np.ndarray) -> np.ndarray:
        return self.low + np.asarray(points, dtype=np.float64) * (self.high - self.low)

    def _anchor(self, which: str) -> Task:
        values = {p.name: getattr(p, which) for p in self.parameters}
        missing = [name for name, v in values.items() if v is None]
        if missing:
            raise ValueError(f"this task space defines no {which} value for {missing}")
        return values

    def hardest(self) -> Task:
        return self._anchor("hardest")

    def easiest(self) -> Task:
        return self._anchor("easiest")


def _whole_number(parameter: Parameter, raw: object) -> int:
    """An integer parameter's value: an int inside the bounds (a float, even 3.0, is refused, so a
    client that sends floats for levels hears of it at once)."""
    if isinstance(raw, bool) or not isinstance(raw, (int, np.integer)):
        raise ValueError(f"task parameter {parameter.name!r} is an integer parameter, got {raw!r}")
    value = int(raw)
    if not parameter.low <= value <= parameter.high:
        raise ValueError(
            f"task parameter {parameter.name!r}={value} is outside its bounds [{parameter.low}, {parameter.high}]"
        )
    return value
