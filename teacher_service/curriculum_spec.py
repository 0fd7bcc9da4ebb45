"""The service's curriculum spec: the teacher kind chooses the model its ``params`` must match.

``common.client.schemas.CurriculumSpec`` is what a client sends and reads back, with ``params`` as a plain
mapping; here each kind has its own spec class, made from the registry of teacher kinds and joined
into one union discriminated by ``teacher``, so a bad parameter is a 422 naming the field and
``/docs`` shows every kind's parameters. A new kind needs no line here.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Annotated, Any, Literal, Union

from pydantic import Field, TypeAdapter, ValidationError, create_model, model_validator
from typing_extensions import Self

from common.client.schemas import CurriculumSpec, CurriculumSpecBase, ParameterSpec
from teacher_service.teachers import TEACHER_KINDS, Teacher, TeacherParams

log = logging.getLogger(__name__)


class TypedSpec(CurriculumSpecBase):
    """A curriculum spec with its teacher's parameters checked; one subclass per kind."""

    teacher: str
    params: TeacherParams

    @model_validator(mode="after")
    def _kind_takes_the_space(self) -> Self:
        teacher = TEACHER_KINDS[self.teacher]
        problem = teacher.space_problem(self.task_space())
        if problem is not None:
            raise ValueError(problem)
        return self

    def to_client_spec(self) -> CurriculumSpec:
        """The same curriculum as the client-side schema that responses carry."""
        return CurriculumSpec.model_validate(self.model_dump())


def _spec_class(kind: str, teacher: type[Teacher]) -> type[TypedSpec]:
    """The spec of one kind: ``teacher`` fixed to its name, ``params`` its parameter model (so
    ``/docs`` names it ``AlpGmmCurriculum`` for ``alp-gmm``)."""
    title = "".join(word.capitalize() for word in kind.split("-")) + "Curriculum"
    spec: type[TypedSpec] = create_model(
        title,
        __base__=TypedSpec,
        teacher=(Literal[kind], ...),  # type: ignore[arg-type]  # a Literal of the kind's name, made at import
        params=(teacher.Params, Field(default_factory=teacher.Params)),
    )
    return spec


SPEC_CLASSES: Mapping[str, type[TypedSpec]] = MappingProxyType(
    {kind: _spec_class(kind, teacher) for kind, teacher in TEACHER_KINDS.items()}
)
"""One spec class per teacher kind, made from the registry (``teachers.TEACHER_KINDS``)."""

if TYPE_CHECKING:
    CurriculumRequest = TypedSpec
else:
    CurriculumRequest = Annotated[Union[tuple(SPEC_CLASSES.values())], Field(discriminator="teacher")]  # noqa: UP007
"""The body of ``PUT /api/v1/curricula/{name}``: the kind's spec class, chosen by ``teacher``. The
type checker sees the base class: the union is built from the registry when the module loads."""

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
