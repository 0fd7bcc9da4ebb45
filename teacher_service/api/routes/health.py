"""Liveness and Prometheus metrics."""

from __future__ import annotations

import os

from fastapi import APIRouter, Response
from prometheus_client import CONTENT_TYPE_LATEST

from common.client.schemas import Health
from teacher_service.api.deps import MetricsDep, RegistryDep

router = APIRouter(tags=["service"])


@router.get("/healthz")
async def healthz(registry: RegistryDep) -> Health:
    failing = registry.writes_failing
    return Health(
        status="ok" if failing is None else "degraded",
        curricula=len(registry),
        writes_failing=failing,
        fits_stopped=registry.fits_stopped,
        pid=os.getpid(),
    )


@router.get(
    "/metrics",
    response_class=Response,
    responses={
        200: {
            "content": {"text/plain": {"schema": {"type": "string"}}},
            "description": "Prometheus text exposition format.",
        }
    },
)
async def metrics(service_metrics: MetricsDep) -> Response:
    return Response(service_metrics.render(), media_type=CONTENT_TYPE_LATEST)
