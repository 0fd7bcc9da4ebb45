"""Error answers that say what went wrong.

JSON-safe 422s: FastAPI's default handler echoes each offending input back; a NaN or infinite
reward cannot be written as JSON, nor a lone surrogate (a task id with a ``\ud800`` escape) as
UTF-8, either of which would turn the client's mistake into a 500. Non-finite numbers are echoed as
strings instead, and lone surrogates as their escapes.

503 for a write the database refused (disk full, read-only file, I/O error): nothing of the request
was stored and the same request can be sent again, so the answer asks for a retry and says why
instead of hiding the cause behind a 500.
"""

from __future__ import annotations

import math
from typing import Any

from fastapi import Request, status
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from teacher_service.store import StoreError

STORE_RETRY_AFTER_S = 5
"""``Retry-After`` of a 503 for a refused write; clients back off further on their own while it lasts."""


def _json_safe(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, str) and not value.isascii():
        return value.encode("utf-8", "backslashreplace").decode("utf-8")
    if isinstance(value, dict):
        return {key: _json_safe(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_json_safe(item) for item in value]
    return value


async def validation_error_handler(request: Request, error: Exception) -> JSONResponse:
    assert isinstance(error, RequestValidationError)
    return JSONResponse(
        status_code=status.HTTP_422_UNPROCESSABLE_CONTENT,
        content={"detail": _json_safe(jsonable_encoder(error.errors()))},
    )


async def store_error_handler(request: Request, error: Exception) -> JSONResponse:
    assert isinstance(error, StoreError)
    return JSONResponse(
        status_code=status.HTTP_503_SERVICE_UNAVAILABLE,
        content={"detail": f"the teacher's database could not store this request: {error}"},
        headers={"Retry-After": str(STORE_RETRY_AFTER_S)},
    )
