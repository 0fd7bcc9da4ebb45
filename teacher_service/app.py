"""The FastAPI application: ``create_app(settings)`` wires the store, the curricula and the routes.

The service is one process with one event loop (SQLite and the live teachers are its state): run
it with a single uvicorn worker.
"""

from __future__ import annotations

import asyncio
import gc
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi.exceptions import RequestValidationError
from starlette.types import ASGIApp

from teacher_service.api.docs import add_offline_docs
from teacher_service.api.errors import store_error_handler, validation_error_handler
from teacher_service.api.hosts import AllowedHosts, AllowedHostsMiddleware
from teacher_service.api.hot_routes import HotRoutes
from teacher_service.api.routes import curricula, health, teachers
from teacher_service.core.config import ANY_HOST, Settings
from teacher_service.dashboard import router as dashboard_router
from teacher_service.metrics import MetricsMiddleware, ServiceMetrics
from teacher_service.registry import CurriculumRegistry
from teacher_service.store import Store, StoreError

YOUNG_GENERATION_THRESHOLD = 20_000
"""Allocations between young-generation collections (Python's default is 700): a request allocates
hundreds of short-lived containers, and collecting that often costs a tenth of the CPU at load."""


def _settle_garbage_collector() -> None:
    """Move everything alive after startup (the imported libraries, the replayed teachers) out of
    the collector's reach. Without this, every full collection walks the hundreds of thousands of
    objects that numpy, scikit-learn and FastAPI leave behind, stalling every request for ~100 ms."""
    gc.collect()
    gc.freeze()
    gc.set_threshold(YOUNG_GENERATION_THRESHOLD, *gc.get_threshold()[1:])


class TeacherServiceApp(FastAPI):
    """FastAPI with ``HotRoutes`` in front of its whole middleware stack, so that drawing tasks and
    reporting results skip the framework's layers (it still serves every other request)."""

    def build_middleware_stack(self) -> ASGIApp:
        settings: Settings = self.state.settings
        names = settings.host_names()
        hosts = None if ANY_HOST in names else AllowedHosts(names)
        return HotRoutes(super().build_middleware_stack(), self.state, settings, self.state.metrics, hosts)


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()
    service_metrics = ServiceMetrics()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        store = Store(settings.db, settings.sqlite_synchronous)
        registry = CurriculumRegistry(store, service_metrics, settings)
        try:
            registry.restore()
        except BaseException:
            store.close()
            raise
        registry.start(asyncio.get_running_loop())
        app.state.registry = registry
        _settle_garbage_collector()
        try:
            yield
        finally:
            registry.close()

    app = TeacherServiceApp(
        title="kuka-curriculum teacher service",
        summary="Hands each episode a task from a curriculum teacher and learns from the results.",
        version="1.0.0",
        lifespan=lifespan,
        max_body_size=settings.max_body_bytes,
        docs_url=None,
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.metrics = service_metrics
    app.add_exception_handler(RequestValidationError, validation_error_handler)
    app.add_exception_handler(StoreError, store_error_handler)
    app.include_router(health.router)
    app.include_router(curricula.router)
    app.include_router(teachers.router)
    app.include_router(dashboard_router)
    add_offline_docs(app)
    app.add_middleware(MetricsMiddleware, metrics=service_metrics)
    if ANY_HOST not in settings.host_names():
        app.add_middleware(AllowedHostsMiddleware, allowed=settings.host_names())
    return app
