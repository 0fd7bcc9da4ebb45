"""The service's curriculum spec: the teacher kind chooses the model its ``params`` must match.

``common.client.schemas.CurriculumSpec`` is what a client sends and reads back, with ``params`` as a plain
mapping; here each kind has its own spec class, joined into one union discriminated by ``teacher``,
so a bad parameter is a 422 naming the field and ``/docs`` shows every kind's parameters.
"""

from __future__ import annotations

import json
import logging
from typing import Annotated, Any, Literal, get_args

from pydantic import Field, TypeAdapter, ValidationError

from common.client.schemas import CurriculumSpec, CurriculumSpecBase, ParameterSpec
from teacher_service.teachers import TeacherParams
from teacher_service.teachers.adr import AdrParams
from teacher_service.teachers.alp_gmm import AlpGmmParams
from teacher_service.teachers.covar_gmm import CovarGmmParams
from teacher_service.teachers.currot import CurrotParams
from teacher_service.teachers.learnability import LearnabilityParams
from teacher_service.teachers.manual import ManualParams
from teacher_service.teachers.riac import RiacParams
from teacher_service.teachers.self_paced import SelfPacedParams
from teacher_service.teachers.uniform import FixedParams, RandomParams

log = logging.getLogger(__name__)


class TypedSpec(CurriculumSpecBase):
    """A curriculum spec with its teacher's parameters checked; one subclass per kind."""

    teacher: str
    params: TeacherParams

    def to_client_spec(self) -> CurriculumSpec:
        """The same curriculum as the client-side schema that responses carry."""
        return CurriculumSpec.model_validate(self.model_dump())


class AlpGmmCurriculum(TypedSpec):
    teacher: Literal["alp-gmm"]
    params: AlpGmmParams = Field(default_factory=AlpGmmParams)


class ManualCurriculum(TypedSpec):
    teacher: Literal["manual"]
    params: ManualParams = Field(default_factory=ManualParams)


class RandomCurriculum(TypedSpec):
    teacher: Literal["random"]
    params: RandomParams = Field(default_factory=RandomParams)


class FixedCurriculum(TypedSpec):
    teacher: Literal["fixed"]
    params: FixedParams = Field(default_factory=FixedParams)


class AdrCurriculum(TypedSpec):
    teacher: Literal["adr"]
    params: AdrParams = Field(default_factory=AdrParams)


class SelfPacedCurriculum(TypedSpec):
    teacher: Literal["self-paced"]
    params: SelfPacedParams = Field(default_factory=SelfPacedParams)


class CurrotCurriculum(TypedSpec):
    teacher: Literal["currot"]
    params: CurrotParams = Field(default_factory=CurrotParams)


class CovarGmmCurriculum(TypedSpec):
    teacher: Literal["covar-gmm"]
    params: CovarGmmParams = Field(default_factory=CovarGmmParams)


class RiacCurriculum(TypedSpec):
    teacher: Literal["riac"]
    params: RiacParams = Field(default_factory=RiacParams)


class LearnabilityCurriculum(TypedSpec):
    teacher: Literal["learnability"]
    params: LearnabilityParams = Field(default_factory=LearnabilityParams)


CurriculumRequest = Annotated[
    AlpGmmCurriculum
    | ManualCurriculum
    | RandomCurriculum
    | FixedCurriculum
    | AdrCurriculum
    | SelfPacedCurriculum
    | CurrotCurriculum
    | CovarGmmCurriculum
    | RiacCurriculum
    | LearnabilityCurriculum,
    Field(discriminator="teacher"),
]
"""The body of ``PUT /api/v1/curricula/{name}``."""

SPEC_CLASSES: dict[str, type[TypedSpec]] = {
    get_args(spec.model_fields["teacher"].annotation)[0]: spec
    for spec in (
        AlpGmmCurriculum,
        ManualCurriculum,
        RandomCurriculum,
        FixedCurriculum,
        AdrCurriculum,
        SelfPacedCurriculum,
        CurrotCurriculum,
        CovarGmmCurriculum,
        RiacCurriculum,
        LearnabilityCurriculum,
    )
}

_ADAPTER: TypeAdapter[CurriculumRequest] = TypeAdapter(CurriculumRequest)


def stored_spec(text: str) -> TypedSpec:
    """A spec read back from the store. One stored by an older version with a value outside
    today's bounds keeps that value (with a warning): refusing it would lose the curriculum.
    Raises ``ValueError`` for a teacher kind this version lacks (see ``registry``)."""
    try:
        spec: TypedSpec = _ADAPTER.validate_json(text)
        return spec
    except ValidationError as error:
        data: dict[str, Any] = json.loads(text)
        spec_class = SPEC_CLASSES.get(data.get("teacher", ""))
        if spec_class is None:
            raise ValueError(f"teacher kind {data.get('teacher')!r} is not in this version") from None
        log.warning("stored curriculum spec is outside today's parameter bounds, kept as it is: %s", error)
        params_class = spec_class.model_fields["params"].annotation
        assert isinstance(params_class, type) and issubclass(params_class, TeacherParams)
        return spec_class.model_construct(
            teacher=data["teacher"],
            space=[ParameterSpec.model_validate(p) for p in data["space"]],
            seed=data.get("seed", 0),
            params=params_class.model_construct(**data.get("params", {})),
        )
