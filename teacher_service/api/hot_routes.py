"""The two requests a fleet sends all the time, drawing tasks and reporting results, served straight
from ASGI in front of the framework.

Through FastAPI each of them passed some fifteen layers (error, telemetry and body-limit middleware,
routing, dependency resolution, response validation) that cost more than the request's own work: a
profile of 1,000 simulated workers (issue 60) found ~45% of the service's samples in those layers
and 16% in the endpoints. Here a request is served only when the framework would have served it
with a 200: addressed to an allowed host, with the write token if one is set, a declared length
within ``KC_MAX_BODY_BYTES``, an ``application/json`` body that validates against the same models,
for a curriculum that is loaded. Anything else goes to the framework unchanged, the body already
read replayed to it, so every refusal (status, body, headers) is the framework's own. The FastAPI
routes stay declared: they are the OpenAPI schema, and they serve what this path hands over.

What a served request does is the routes' own work (``issue_tasks``, ``apply_results``), answered
with the same JSON bytes (pydantic's ``dump_json``, as FastAPI does), the same 422 and 503 answers
for refused results and refused writes, and the same request metrics.
"""

from __future__ import annotations

import re
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from fastapi.exceptions import RequestValidationError
from fastapi.security.utils import get_authorization_scheme_param
from pydantic import BaseModel, TypeAdapter, ValidationError
from starlette.datastructures import State
from starlette.requests import Request
from starlette.responses import PlainTextResponse, Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from common.client.schemas import API_PREFIX, CURRICULUM_NAME_PATTERN, ResultAck, ResultBatch, TaskBatch, TaskRequest
from teacher_service.api.deps import write_token_matches
from teacher_service.api.errors import store_error_handler, validation_error_handler
from teacher_service.api.hosts import AllowedHosts, host_name
from teacher_service.api.routes.curricula import apply_results, issue_tasks
from teacher_service.core.config import Settings
from teacher_service.curricula import Curriculum, UnknownCurriculum
from teacher_service.metrics import ServiceMetrics
from teacher_service.registry import CurriculumRegistry, CurriculumUnloadable
from teacher_service.store import StoreError

_NAME = CURRICULUM_NAME_PATTERN.removeprefix("^").removesuffix("$")
_HOT_PATH = re.compile(rf"{re.escape(API_PREFIX)}/curricula/({_NAME})/(tasks|results)")
"""Matched whole (``fullmatch``): the anchors' ``$`` would also let a name end in a newline."""


@dataclass(frozen=True)
class HotEndpoint:
    route: str
    """The route's template, as the request metrics name it."""
    body: type[BaseModel]
    answer: TypeAdapter[Any]
    work: Callable[[Curriculum, Any], Awaitable[BaseModel]]


HOT_ENDPOINTS = {
    "tasks": HotEndpoint(f"{API_PREFIX}/curricula/{{name}}/tasks", TaskRequest, TypeAdapter(TaskBatch), issue_tasks),
    "results": HotEndpoint(
        f"{API_PREFIX}/curricula/{{name}}/results", ResultBatch, TypeAdapter(ResultAck), apply_results
    ),
}


class HotRoutes:
    """ASGI middleware serving the hot endpoints' well-formed requests; ``app`` gets every other."""

    def __init__(
        self, app: ASGIApp, state: State, settings: Settings, metrics: ServiceMetrics, hosts: AllowedHosts | None
    ) -> None:
        self.app = app
        self._state = state
        """The app's state, where the lifespan puts the registry."""
        self._settings = settings
        self._metrics = metrics
        self._hosts = hosts
        """None when any host is answered."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        match = _HOT_PATH.fullmatch(scope["path"]) if scope["type"] == "http" and scope["method"] == "POST" else None
        if match is None or scope.get("root_path") or not self._admits(scope["headers"]):
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        name, endpoint = match[1], HOT_ENDPOINTS[match[2]]
        read, body = await self._read_body(receive)
        request = _parse(endpoint.body, body) if body is not None else None
        curriculum = self._curriculum(name) if request is not None else None
        if curriculum is None:
            await self.app(scope, _replaying(read, receive), send)
            return
        status = 500
        try:
            try:
                response = await self._answer(scope, endpoint, curriculum, request)
            except Exception:
                await PlainTextResponse("Internal Server Error", status_code=500)(scope, receive, send)
                raise  # for uvicorn to log, as the framework's error middleware does
            status = response.status_code
            await response(scope, receive, send)
        finally:
            self._metrics.requests.labels("POST", endpoint.route, str(status)).inc()
            self._metrics.request_seconds.labels("POST", endpoint.route).observe(time.perf_counter() - started)

    def _admits(self, headers: list[tuple[bytes, bytes]]) -> bool:
        """The checks the framework makes of the headers: host, token, declared body size and JSON."""
        host = authorization = content_type = length = None
        for key, value in headers:  # the first of repeated headers counts, as Starlette reads them
            if key == b"host" and host is None:
                host = value
            elif key == b"authorization" and authorization is None:
                authorization = value
            elif key == b"content-type" and content_type is None:
                content_type = value
            elif key == b"content-length" and length is None:
                length = value
        if content_type != b"application/json" or length is None or not length.isdigit():
            return False
        if int(length) > self._settings.max_body_bytes:
            return False
        if self._hosts is not None and not self._hosts.allows(host_name((host or b"").decode("latin-1"))):
            return False
        return self._token_matches(authorization)

    def _token_matches(self, authorization: bytes | None) -> bool:
        """``require_token``'s verdict on this ``Authorization`` header, read as ``HTTPBearer`` reads it."""
        header = authorization.decode("latin-1") if authorization is not None else None
        scheme, credentials = get_authorization_scheme_param(header)
        given = credentials if header and scheme.lower() == "bearer" and credentials else ""
        return write_token_matches(self._settings, given)

    async def _read_body(self, receive: Receive) -> tuple[list[Message], bytes | None]:
        """The messages read, and the body; None if the client left or the body outgrew the limit."""
        read: list[Message] = []
        size = 0
        while True:
            message = await receive()
            read.append(message)
            if message["type"] != "http.request":
                return read, None
            size += len(message.get("body", b""))
            if size > self._settings.max_body_bytes:
                return read, None
            if not message.get("more_body", False):
                return read, b"".join(message.get("body", b"") for message in read)

    def _curriculum(self, name: str) -> Curriculum | None:
        registry: CurriculumRegistry = self._state.registry
        try:
            return registry.get(name)
        except (UnknownCurriculum, CurriculumUnloadable):
            return None

    async def _answer(self, scope: Scope, endpoint: HotEndpoint, curriculum: Curriculum, request: Any) -> Response:
        """Do the endpoint's work; the answer, as the framework would give it."""
        try:
            answer = await endpoint.work(curriculum, request)
        except RequestValidationError as invalid:
            return await validation_error_handler(Request(scope), invalid)
        except StoreError as refused:
            return await store_error_handler(Request(scope), refused)
        return Response(endpoint.answer.dump_json(answer), media_type="application/json")


def _parse(model: type[BaseModel], body: bytes) -> BaseModel | None:
    """The request body as ``model``, or None where the framework would refuse it.

    From the bytes in one pass; what this accepts, ``json.loads`` and the model (the framework's
    way) accept too, with the same values. Where they might differ (a lone surrogate escape, which
    this refuses), the framework answers."""
    try:
        return model.model_validate_json(body)
    except ValidationError:
        return None


def _replaying(read: list[Message], receive: Receive) -> Receive:
    """A ``receive`` giving back the messages already read, then the rest."""
    pending = list(read)

    async def replay() -> Message:
        return pending.pop(0) if pending else await receive()

    return replay
