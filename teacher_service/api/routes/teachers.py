"""The teacher kinds this service offers, with their parameters, read from the kinds' own models.

Nothing here is written by hand per kind: a kind registered in ``TEACHER_KINDS`` is listed with its
class docstring's summary and its ``Params`` model's fields (defaults, bounds, docs), so the list
cannot drift from what ``PUT /api/v1/curricula/{name}`` accepts.
"""

from __future__ import annotations

import functools
import inspect
from typing import Any

from fastapi import APIRouter

from common.client.schemas import API_PREFIX, TeacherKindInfo, TeacherKindList, TeacherParameterInfo
from teacher_service.teachers import TEACHER_KINDS, Teacher

router = APIRouter(prefix=f"{API_PREFIX}/teachers", tags=["teachers"])


def _inline(schema: Any, definitions: dict[str, Any]) -> Any:
    """``schema`` with every ``$ref`` into the model's ``$defs`` replaced by what it names."""
    if isinstance(schema, dict):
        reference = schema.get("$ref")
        if isinstance(reference, str) and reference.startswith("#/$defs/"):
            return _inline(definitions[reference.removeprefix("#/$defs/")], definitions)
        return {key: _inline(value, definitions) for key, value in schema.items()}
    if isinstance(schema, list):
        return [_inline(item, definitions) for item in schema]
    return schema


def _first(branches: list[dict[str, Any]], key: str) -> Any:
    return next((branch[key] for branch in branches if key in branch), None)


def _parameter(name: str, schema: dict[str, Any]) -> TeacherParameterInfo:
    branches = schema.get("anyOf", [schema])
    types = [branch.get("type", "object") for branch in branches]
    max_items = _first(branches, "maxItems")
    return TeacherParameterInfo(
        name=name,
        type=" | ".join(dict.fromkeys(types)),
        default=schema.get("default"),
        doc=" ".join(schema.get("description", "").split()),
        minimum=_first(branches, "minimum"),
        maximum=_first(branches, "maximum"),
        exclusive_minimum=_first(branches, "exclusiveMinimum"),
        exclusive_maximum=_first(branches, "exclusiveMaximum"),
        max_items=_first(branches, "maxProperties") if max_items is None else max_items,
        choices=_first(branches, "enum"),
        json_schema=schema,
    )


def describe_kind(kind: str, teacher: type[Teacher]) -> TeacherKindInfo:
    """A kind's summary (its class docstring's first paragraph) and its parameters."""
    summary = inspect.cleandoc(teacher.__doc__ or "").split("\n\n")[0]
    model_schema = teacher.Params.model_json_schema()
    properties = _inline(model_schema.get("properties", {}), model_schema.get("$defs", {}))
    return TeacherKindInfo(
        kind=kind,
        summary=" ".join(summary.split()),
        parameter_types=sorted(teacher.parameter_types),
        parameters=[_parameter(name, schema) for name, schema in properties.items()],
    )


@functools.cache
def _catalogue() -> TeacherKindList:
    return TeacherKindList(teachers=[describe_kind(kind, teacher) for kind, teacher in sorted(TEACHER_KINDS.items())])


@router.get("")
async def list_teachers() -> TeacherKindList:
    """Every teacher kind a curriculum can use: what it does and its parameters, with their
    defaults, bounds and docs, as the request schema of ``PUT /api/v1/curricula/{name}`` has them."""
    return _catalogue()
