"""The teacher service's HTTP API as pydantic models, shared by the service and its client.

Request models forbid unknown fields so a misspelt key is a 422, not a silently ignored value.
Rewards and bounds must be finite: JSON parsers accept ``NaN`` and ``Infinity``, teachers must not.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_serializer, model_validator
from typing_extensions import Self

from common.client.task_space import Parameter, ParameterType, TaskSpace

API_PREFIX = "/api/v1"

TEACHER_KIND_PATTERN = r"^[a-z][a-z0-9-]{0,31}$"
TeacherKind = Annotated[str, Field(min_length=1, max_length=32, pattern=TEACHER_KIND_PATTERN)]
"""A teacher kind's name, such as ``alp-gmm``. The service knows its kinds (``GET /api/v1/teachers``
lists them, an unknown one is a 422), so this client needs no change when the service gains one."""

TEACHER_LABELS: Mapping[str, str] = MappingProxyType(
    {
        "alp-gmm": "ALP-GMM",
        "manual": "Manual lesson plan",
        "random": "Uniform random tasks",
        "fixed": "No curriculum: hardest task only",
        "adr": "ADR",
        "self-paced": "Self-paced (SPDL)",
        "currot": "CURROT",
        "covar-gmm": "Covar-GMM",
        "riac": "RIAC",
        "learnability": "Learnability (SFL)",
        "plr": "Prioritized level replay (PLR)",
        "learning-progress": "Learning progress",
    }
)
"""Each teacher kind the service ships, in its registry's order, with the name reports and plots give it: the
one list of kinds and labels the learner reads, without importing the service (a test holds it to the
service's registry)."""

CURRICULUM_NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"
MAX_TASKS_PER_REQUEST = 1024
MAX_RESULTS_PER_REQUEST = 1024
MAX_SEED = 2**63 - 1
MAX_SCORE = 1e12
"""A result's score is bounded so every teacher's arithmetic on it stays finite."""
"""Seeds and lengths are stored as SQLite integers, which are signed 64-bit."""

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]

TaskValues = dict[str, int | float]
"""A task as the API carries it: an integer parameter's value stays an int (a float one is a float)."""


class _Request(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ParameterSpec(_Request):
    """One dimension of a task space; ``hardest``/``easiest`` anchor the manual and fixed teachers."""

    name: str = Field(min_length=1, max_length=64)
    low: FiniteFloat
    high: FiniteFloat
    hardest: FiniteFloat | None = None
    easiest: FiniteFloat | None = None
    type: ParameterType = Field(
        default="float",
        description="`float`: any value from low to high. `integer`: the whole numbers from low to high, both "
        "included (a level seed, a layout choice); tasks then carry ints. Left out, a parameter is a float.",
    )

    @field_serializer("low", "high", "hardest", "easiest")
    def _whole_for_integers(self, value: float | None) -> int | float | None:
        """An integer parameter's bounds and anchors go out as the whole numbers they are (``"high": 199``, not
        ``199.0``), so a registration echoes what was sent."""
        if value is not None and self.type == "integer" and float(value).is_integer():
            return int(value)
        return value

    def to_parameter(self) -> Parameter:
        return Parameter(self.name, self.low, self.high, hardest=self.hardest, easiest=self.easiest, type=self.type)

    @classmethod
    def from_parameter(cls, parameter: Parameter) -> ParameterSpec:
        return cls(
            name=parameter.name,
            low=parameter.low,
            high=parameter.high,
            hardest=parameter.hardest,
            easiest=parameter.easiest,
            type=parameter.type,
        )


class CurriculumSpecBase(_Request):
    """What every curriculum has besides its teacher: the task space and the seed."""

    space: list[ParameterSpec] = Field(min_length=1, max_length=64)
    seed: int = Field(default=0, ge=0, le=MAX_SEED)

    @model_validator(mode="after")
    def _space_is_valid(self) -> Self:
        space = self.task_space()
        for parameter in space.parameters:
            if not math.isfinite(parameter.high - parameter.low):
                raise ValueError(f"parameter {parameter.name!r}: the width high - low overflows a float")
        return self

    def task_space(self) -> TaskSpace:
        return TaskSpace(p.to_parameter() for p in self.space)


class CurriculumSpec(CurriculumSpecBase):
    """What defines a curriculum: two specs are the same curriculum exactly when they are equal.

    The service checks ``params`` against the teacher kind's own model (``GET /docs`` shows each
    kind's parameters with their bounds); here they stay a plain mapping so a client needs no
    teacher code."""

    teacher: TeacherKind
    params: dict[str, Any] = Field(default_factory=dict, description="Teacher hyperparameters; see the teacher kinds.")


class CurriculumCounters(BaseModel):
    tasks_issued: int
    results_received: int
    results_per_second: float = Field(description="Results accepted per second over the recent window.")
    tasks_outstanding: int = Field(description="Issued tasks awaiting a result (not yet expired).")
    tasks_expired: int = Field(default=0, description="Tasks that expired with no result since the service started.")
    fits_completed: int
    fits_pending: int
    last_fit_at: float | None = Field(description="Unix time the last fit was installed.")
    fits_stopped: str | None = Field(
        default=None,
        description="Why this service runs no fits any more (its fit processes kept dying); null while fits run.",
    )
    writes_failing: str | None = Field(
        default=None,
        description="Why this service's database refuses writes (a full disk), while it does: new tasks and "
        "results are answered 503 until the first write succeeds; null while writes work.",
    )


class CurriculumInfo(BaseModel):
    name: str
    config: CurriculumSpec
    created_at: float
    counters: CurriculumCounters


class CurriculumList(BaseModel):
    curricula: list[CurriculumInfo]


class TaskRequest(_Request):
    count: int = Field(default=1, ge=1, le=MAX_TASKS_PER_REQUEST)


class IssuedTask(BaseModel):
    task_id: str
    params: TaskValues
    score_only: bool = Field(
        default=False,
        description="Play this episode and report its result, but leave its transitions out of the policy "
        "update: robust PLR scores a new level this way before it may train on it.",
    )


class TaskBatch(BaseModel):
    tasks: list[IssuedTask]


class ResultItem(_Request):
    task_id: str = Field(min_length=1, max_length=200)
    reward: FiniteFloat
    success: bool | None = None
    length: int | None = Field(default=None, ge=0, le=MAX_SEED)
    score: FiniteFloat | None = Field(
        default=None,
        ge=-MAX_SCORE,
        le=MAX_SCORE,
        description="How much the episode has left to teach, as the learner measures it (PLR's positive value "
        "loss: the mean over its steps of max(GAE advantage, 0)). The level kinds use it; without it they "
        "fall back on the return or success, and the other kinds ignore it.",
    )


class ResultBatch(_Request):
    results: list[ResultItem] = Field(max_length=MAX_RESULTS_PER_REQUEST)


class ResultAck(BaseModel):
    accepted: int = Field(description="Results applied by this request.")
    duplicates: int = Field(description="Results for tasks that already had one; ignored.")
    expired: int = Field(
        default=0,
        description="Results for tasks that had expired (KC_TASK_TTL_S, KC_TASK_WINDOW) before they came; ignored.",
    )


class FitEvent(BaseModel):
    index: int
    started_at: float
    finished_at: float
    duration_s: float
    replayed: bool = Field(
        description="Came back with a restart: installed from its stored model, or run again because the"
        " service died before recording it."
    )
    error: str | None = None


class RecentResult(BaseModel):
    task_id: str
    params: TaskValues
    reward: float
    success: bool | None
    length: int | None
    received_at: float
    score: float | None = None


class CurriculumState(BaseModel):
    curriculum: CurriculumInfo
    teacher: dict[str, Any] = Field(description="The teacher's own description (kind-specific).")
    fits: list[FitEvent] = Field(description="Recent fits, oldest first.")
    recent_results: list[RecentResult] = Field(description="Recent results, oldest first.")


class Health(BaseModel):
    status: Literal["ok", "degraded"] = Field(
        default="ok", description="`degraded` while the database refuses writes (see `writes_failing`)."
    )
    curricula: int
    writes_failing: str | None = Field(
        default=None,
        description="Why the database refuses writes (a full disk, a read-only file) while it does: writes "
        "answer 503 with the same reason, reads and the tasks already issued still work, and the service "
        "recovers by itself at the first write that succeeds.",
    )
    fits_stopped: str | None = Field(
        default=None,
        description="Why no teacher model fits run any more (tasks are still served from the last models).",
    )
    pid: int = Field(
        description="The service's process id: a caller that started the service tells its own answer from "
        "another service's that took the port first.",
    )


class ErrorMessage(BaseModel):
    detail: str


class TeacherParameterInfo(BaseModel):
    """One parameter of a teacher kind, as its parameter model declares it."""

    name: str
    type: str = Field(description="JSON type(s), e.g. 'integer' or 'number | null'.")
    default: Any = Field(description="Used when the parameter is left out.")
    doc: str = Field(description="What the parameter does.")
    minimum: float | None = Field(description="Smallest value allowed (inclusive), if bounded below.")
    maximum: float | None = Field(description="Largest value allowed (inclusive), if bounded above.")
    exclusive_minimum: float | None = Field(description="Values must exceed this, if bounded so.")
    exclusive_maximum: float | None = Field(description="Values must stay below this, if bounded so.")
    max_items: int | None = Field(description="Most items of a list or entries of a mapping, if bounded.")
    choices: list[Any] | None = Field(description="The values allowed, for a choice among names.")
    json_schema: dict[str, Any] = Field(description="The parameter's full JSON schema.")


class TeacherKindInfo(BaseModel):
    kind: str = Field(description="The `teacher` of a curriculum request.")
    summary: str = Field(description="What the teacher does, in one line.")
    parameter_types: list[ParameterType] = Field(
        description="The task parameter types (`float`, `integer`) its task spaces may hold."
    )
    parameters: list[TeacherParameterInfo] = Field(description="Its `params`, in declaration order.")


class TeacherKindList(BaseModel):
    teachers: list[TeacherKindInfo]
