"""The curriculum task space: named, bounded parameters that set an episode's difficulty.

A task is a plain ``dict`` of parameter name to float. ``TaskSpace`` is generic (the teacher
service builds spaces from HTTP requests); ``KUKA_TASK_SPACE`` is the book's six-parameter space and
``KUKA_HARD_TASK_SPACE`` the harder family of ``KukaGraspHard-v0``: the same six plus three more.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from common import ENV_ID, HARD_ENV_ID

Task = dict[str, float]


@dataclass(frozen=True)
class Parameter:
    """One task dimension. ``easiest``/``hardest`` are optional anchors used by curricula."""

    name: str
    low: float
    high: float
    hardest: float | None = None
    easiest: float | None = None
    doc: str = ""

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("parameter name must be non-empty")
        if not (math.isfinite(self.low) and math.isfinite(self.high)) or self.low > self.high:
            raise ValueError(f"parameter {self.name!r}: need finite low <= high, got [{self.low}, {self.high}]")
        for label, value in (("hardest", self.hardest), ("easiest", self.easiest)):
            if value is not None and not self.low <= value <= self.high:
                raise ValueError(f"parameter {self.name!r}: {label}={value} outside [{self.low}, {self.high}]")


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
        """Map a vector to a task, clipping into the box (sampling noise can step outside)."""
        clipped = np.clip(np.asarray(values, dtype=np.float64), self.low, self.high)
        return {name: float(v) for name, v in zip(self.names, clipped, strict=True)}

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


DEFAULT_JP2 = 0.413184
DEFAULT_JP4 = -1.589317

KUKA_TASK_SPACE = TaskSpace(
    [
        Parameter(
            "rnd_obj_x",
            0.0,
            1.0,
            hardest=1.0,
            easiest=0.0,
            doc="Share of the block's random x range used: x = 0.55 + 0.12 * U * rnd_obj_x.",
        ),
        Parameter(
            "rnd_obj_y",
            0.0,
            1.0,
            hardest=1.0,
            easiest=0.0,
            doc="Share of the block's random y range used: y = bias_obj_y + 0.2 * U * rnd_obj_y.",
        ),
        Parameter(
            "rnd_obj_ang",
            0.0,
            1.0,
            hardest=1.0,
            easiest=0.0,
            doc="Share of the block's random yaw range used: yaw = pi/2 + pi * U * rnd_obj_ang.",
        ),
        Parameter(
            "jp2",
            DEFAULT_JP2,
            1.3,
            hardest=DEFAULT_JP2,
            easiest=1.3,
            doc="Start position of arm joint 2 (index 1); higher starts the gripper lower.",
        ),
        Parameter(
            "jp4",
            DEFAULT_JP4,
            -1.0,
            hardest=DEFAULT_JP4,
            easiest=-1.0,
            doc="Start position of arm joint 4 (index 3); compensates the reach when jp2 is raised.",
        ),
        Parameter(
            "bias_obj_y",
            0.0,
            0.04,
            hardest=0.0,
            easiest=0.04,
            doc="Offset of the block's y placement, aligning it with the gripper's start.",
        ),
    ]
)

MOVE_SCALE_HARDEST = 0.1
"""The hard family's slowest gripper: 0.5 mm per step at full action, 20 cm in 400 of the ~800 steps
its descent takes from the book's hardest start."""

KUKA_HARD_TASK_SPACE = TaskSpace(
    [
        *KUKA_TASK_SPACE.parameters,
        Parameter(
            "obj_far",
            0.0,
            1.0,
            hardest=1.0,
            easiest=0.0,
            doc="Share of the way from the book's placement to a uniform point of the reachable tray far from "
            "the gripper's start (common.kuka_env.FAR_MIN_DISTANCE or more).",
        ),
        Parameter(
            "shaping",
            0.0,
            1.0,
            hardest=0.0,
            easiest=1.0,
            doc="Weight of the reward's block-distance penalty: 1 is the book's reward, 0 pays the success "
            "bonus alone (less the wrist's rotation cost).",
        ),
        Parameter(
            "move_scale",
            MOVE_SCALE_HARDEST,
            1.0,
            hardest=MOVE_SCALE_HARDEST,
            easiest=1.0,
            doc="Share of the book's 5 mm per step that a full x or y action moves the gripper: at 0.1 a "
            "random walk spreads about 1 cm over an episode, while steady moves still cross the tray.",
        ),
    ]
)

KUKA_HARD_BOOK_HARDEST: Task = {**KUKA_TASK_SPACE.hardest(), "obj_far": 0.0, "shaping": 1.0, "move_scale": 1.0}
"""The book's hardest task (its evaluation setting) as a point of the hard family."""

TASK_SPACES: dict[str, TaskSpace] = {ENV_ID: KUKA_TASK_SPACE, HARD_ENV_ID: KUKA_HARD_TASK_SPACE}
"""Each registered KUKA environment's task space, by gymnasium id."""


def task_space_for(env_id: str) -> TaskSpace:
    """The task space of a registered KUKA environment; ``ValueError`` names the known ids."""
    try:
        return TASK_SPACES[env_id]
    except KeyError:
        raise ValueError(f"unknown environment {env_id!r}; expected one of {', '.join(TASK_SPACES)}") from None
