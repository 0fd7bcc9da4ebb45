"""The interactive API docs at ``/docs``, with Swagger UI served from the installed
``swagger-ui-bundle-v2`` package, as the dashboard serves Plotly from ``plotly``.

FastAPI's own page loads Swagger UI from a CDN and stays blank on a machine without internet; this
one loads nothing from outside the service. (FastAPI's ``/redoc`` page, also from a CDN, is off.)
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles
from swagger_ui_bundle import swagger_ui_path

DOCS_URL = "/docs"
ASSETS_URL = f"{DOCS_URL}/assets"
SWAGGER_UI_DIR = Path(str(swagger_ui_path))


def add_offline_docs(app: FastAPI) -> None:
    """Serve ``/docs`` and Swagger UI's files; make ``app`` with ``docs_url=None, redoc_url=None``."""
    app.mount(ASSETS_URL, StaticFiles(directory=SWAGGER_UI_DIR), name="swagger-ui")

    @app.get(DOCS_URL, include_in_schema=False)
    async def swagger_ui(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "").rstrip("/")  # behind a proxy under a path prefix
        return get_swagger_ui_html(
            openapi_url=f"{root}{app.openapi_url}",
            title=f"{app.title}: API docs",
            swagger_js_url=f"{root}{ASSETS_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{root}{ASSETS_URL}/swagger-ui.css",
            swagger_favicon_url=f"{root}{ASSETS_URL}/favicon-32x32.png",
        )
