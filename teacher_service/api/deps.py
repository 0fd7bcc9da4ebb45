"""Typed dependencies shared by the route handlers.

Each one reads the app state directly instead of nesting other dependencies: every level costs
FastAPI tens of microseconds a request, which shows at thousands of requests a second.
"""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import Depends, HTTPException, Path, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from common.client.schemas import CURRICULUM_NAME_PATTERN
from teacher_service.core.config import Settings
from teacher_service.curricula import Curriculum, UnknownCurriculum
from teacher_service.metrics import ServiceMetrics
from teacher_service.registry import CurriculumRegistry, CurriculumUnloadable


async def get_registry(request: Request) -> CurriculumRegistry:
    registry: CurriculumRegistry = request.app.state.registry
    return registry


async def get_metrics(request: Request) -> ServiceMetrics:
    metrics: ServiceMetrics = request.app.state.metrics
    return metrics


RegistryDep = Annotated[CurriculumRegistry, Depends(get_registry)]
MetricsDep = Annotated[ServiceMetrics, Depends(get_metrics)]

CurriculumName = Annotated[
    str,
    Path(pattern=CURRICULUM_NAME_PATTERN, description="Letters, digits, '_', '.' and '-'; up to 64 characters."),
]


async def get_curriculum(name: CurriculumName, request: Request) -> Curriculum:
    registry: CurriculumRegistry = request.app.state.registry
    try:
        return registry.get(name)
    except UnknownCurriculum:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no curriculum named {name!r}") from None
    except CurriculumUnloadable as unloadable:
        raise HTTPException(status.HTTP_409_CONFLICT, str(unloadable)) from None


CurriculumDep = Annotated[Curriculum, Depends(get_curriculum)]

_bearer = HTTPBearer(auto_error=False, description="Needed on PUT and POST when KC_TEACHER_TOKEN is set.")


def write_token_matches(settings: Settings, given: str) -> bool:
    """Whether ``given`` (a bearer token, or empty) may write: any may when no token is set."""
    if settings.teacher_token is None:
        return True
    return hmac.compare_digest(given.encode(), settings.teacher_token.get_secret_value().encode())


async def require_token(
    request: Request, credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
) -> None:
    """Guard writes with the shared token; reads stay open so dashboards need no secret."""
    settings: Settings = request.app.state.settings
    if not write_token_matches(settings, credentials.credentials if credentials is not None else ""):
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            "this service needs 'Authorization: Bearer <token>' with the token in KC_TEACHER_TOKEN",
            headers={"WWW-Authenticate": "Bearer"},
        )


WriteAccess = Depends(require_token)
