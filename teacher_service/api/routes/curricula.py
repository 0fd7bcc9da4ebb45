"""Curricula: create, inspect, draw tasks from, and report results to."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Query, Response, status
from fastapi.exceptions import RequestValidationError

from common.client.schemas import (
    API_PREFIX,
    CurriculumInfo,
    CurriculumList,
    CurriculumState,
    ErrorMessage,
    ResultAck,
    ResultBatch,
    TaskBatch,
    TaskRequest,
)
from teacher_service.api.deps import CurriculumDep, CurriculumName, RegistryDep, WriteAccess
from teacher_service.api.responses import curriculum_info, curriculum_state
from teacher_service.curricula import Curriculum, CurriculumConflict, InvalidResults
from teacher_service.curriculum_spec import CurriculumRequest

router = APIRouter(prefix=f"{API_PREFIX}/curricula", tags=["curricula"])

_NOT_FOUND: dict[int | str, dict[str, Any]] = {
    404: {"model": ErrorMessage, "description": "No curriculum has this name."},
    409: {
        "model": ErrorMessage,
        "description": "A curriculum of this name is stored, but this version could not load it; the detail says why.",
    },
}
_WRITE: dict[int | str, dict[str, Any]] = {
    400: {"model": ErrorMessage, "description": "The body could not be read as JSON text (e.g. it is not UTF-8)."},
    401: {"model": ErrorMessage, "description": "KC_TEACHER_TOKEN is set and the bearer token is missing or wrong."},
    413: {
        "description": "The request body is larger than the service accepts (KC_MAX_BODY_BYTES).",
        "content": {
            "text/plain": {"schema": {"type": "string"}},
            "application/json": {"schema": ErrorMessage.model_json_schema()},
        },
    },
    503: {
        "model": ErrorMessage,
        "description": "The database refused the write (e.g. disk full); nothing was stored. Retry after "
        "the Retry-After header's seconds: results are idempotent, so resending is safe.",
    },
}


@router.get("")
async def list_curricula(registry: RegistryDep) -> CurriculumList:
    return CurriculumList(curricula=[curriculum_info(curriculum) for curriculum in registry])


@router.put(
    "/{name}",
    status_code=status.HTTP_201_CREATED,
    dependencies=[WriteAccess],
    responses={
        200: {"model": CurriculumInfo, "description": "An identical curriculum already exists; nothing changed."},
        409: {"model": ErrorMessage, "description": "A different curriculum already has this name."},
        **_WRITE,
    },
)
async def put_curriculum(
    name: CurriculumName, spec: CurriculumRequest, registry: RegistryDep, response: Response
) -> CurriculumInfo:
    """Create a curriculum: one teacher over one task space. Idempotent for an identical body
    (parameters left out count as their defaults). Each teacher kind's parameters, with their
    bounds and defaults, are in the request schema below."""
    try:
        curriculum, created = await registry.create(name, spec)
    except CurriculumConflict as conflict:
        raise HTTPException(status.HTTP_409_CONFLICT, str(conflict)) from None
    except ValueError as error:
        raise RequestValidationError(
            [{"loc": ["body", "params"], "msg": str(error), "type": "value_error", "input": spec.params.model_dump()}]
        ) from None
    if not created:
        response.status_code = status.HTTP_200_OK
    return curriculum_info(curriculum)


@router.get("/{name}", responses=_NOT_FOUND)
async def get_curriculum(curriculum: CurriculumDep) -> CurriculumInfo:
    return curriculum_info(curriculum)


async def issue_tasks(curriculum: Curriculum, request: TaskRequest) -> TaskBatch:
    """``draw_tasks``'s work; ``hot_routes`` serves it too."""
    return TaskBatch(tasks=await curriculum.issue(request.count))


async def apply_results(curriculum: Curriculum, batch: ResultBatch) -> ResultAck:
    """``report_results``'s work; ``hot_routes`` serves it too. Results the curriculum refuses are a
    ``RequestValidationError`` naming them."""
    try:
        return await curriculum.report(batch.results)
    except InvalidResults as invalid:
        raise RequestValidationError(invalid.errors) from None


@router.post("/{name}/tasks", dependencies=[WriteAccess], responses={**_NOT_FOUND, **_WRITE})
async def draw_tasks(curriculum: CurriculumDep, request: TaskRequest) -> TaskBatch:
    """Draw tasks from the teacher's current model; they are on disk before the answer is sent."""
    return await issue_tasks(curriculum, request)


@router.post("/{name}/results", dependencies=[WriteAccess], responses={**_NOT_FOUND, **_WRITE})
async def report_results(curriculum: CurriculumDep, batch: ResultBatch) -> ResultAck:
    """Report episode results. Idempotent per task id; all or nothing: one bad item (a 422 naming
    it) and no result of the request is applied."""
    return await apply_results(curriculum, batch)


@router.get("/{name}/state", responses=_NOT_FOUND)
async def get_state(
    curriculum: CurriculumDep,
    recent: Annotated[int | None, Query(ge=0, description="Recent results to include; all kept by default.")] = None,
) -> CurriculumState:
    """The teacher's own state, recent fits, and recent results with their tasks."""
    return curriculum_state(curriculum, len(curriculum.recent_results) if recent is None else recent)
