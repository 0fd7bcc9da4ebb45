"""The live dashboard: two HTML pages and the files they load.

The pages are shells: the browser fills them by polling the same public JSON API the workers use,
so the dashboard needs nothing from the service's internals and, when the service restarts, keeps
its last picture on screen and says the teacher is unreachable until it answers again. Plotly's
JavaScript comes from the installed ``plotly`` package, so a dashboard never reaches the internet.
"""

from __future__ import annotations

import html
from importlib import metadata, resources
from pathlib import Path
from string import Template
from typing import Annotated

from fastapi import APIRouter, HTTPException, Request
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, HTMLResponse

from common.client.schemas import API_PREFIX, CURRICULUM_NAME_PATTERN

PACKAGE_DIR = Path(__file__).parent
PLOTLY_JS = Path(str(resources.files("plotly") / "package_data" / "plotly.min.js"))
PLOTLY_ASSET = f"plotly-{metadata.version('plotly')}.min.js"

ASSETS: dict[str, tuple[Path, str]] = {
    PLOTLY_ASSET: (PLOTLY_JS, "text/javascript"),
    "dashboard.js": (PACKAGE_DIR / "static" / "dashboard.js", "text/javascript"),
    "dashboard.css": (PACKAGE_DIR / "static" / "dashboard.css", "text/css"),
}
"""Everything the pages load, by URL name. Plotly's name carries its version so browsers may keep
it for good; the dashboard's own files are small and revalidated on every page load."""

IMMUTABLE = "public, max-age=31536000, immutable"
REVALIDATE = "no-cache"

TEMPLATES = {
    path.name: Template(path.read_text(encoding="utf-8")) for path in (PACKAGE_DIR / "templates").glob("*.html")
}

router = APIRouter(include_in_schema=False)


def _page(template: str, request: Request, **values: str) -> HTMLResponse:
    """Fill a page template; every value is HTML-escaped, and ``root`` lets the service sit
    behind a proxy under a path prefix."""
    filled = TEMPLATES[template].substitute(
        root=html.escape(request.scope.get("root_path", "").rstrip("/")),
        api=html.escape(API_PREFIX),
        plotly=html.escape(PLOTLY_ASSET),
        **{key: html.escape(value) for key, value in values.items()},
    )
    return HTMLResponse(filled, headers={"Cache-Control": REVALIDATE})


@router.get("/", response_class=HTMLResponse)
async def curricula_page(request: Request) -> HTMLResponse:
    """Every curriculum the service holds, with its counters."""
    return _page("curricula.html", request)


@router.get("/curricula/{name}", response_class=HTMLResponse)
async def curriculum_page(
    request: Request, name: Annotated[str, PathParam(pattern=CURRICULUM_NAME_PATTERN)]
) -> HTMLResponse:
    """One curriculum as it trains. The page is served even before the curriculum exists, so a
    tab opened ahead of a training run fills in once the run creates it."""
    return _page("curriculum.html", request, name=name)


@router.get("/dashboard/assets/{asset}")
async def dashboard_asset(asset: str) -> FileResponse:
    if asset not in ASSETS:
        raise HTTPException(status_code=404, detail=f"no dashboard asset named {asset!r}")
    path, media_type = ASSETS[asset]
    cache = IMMUTABLE if asset == PLOTLY_ASSET else REVALIDATE
    return FileResponse(path, media_type=media_type, headers={"Cache-Control": cache})
