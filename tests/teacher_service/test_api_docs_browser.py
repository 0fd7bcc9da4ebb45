"""The interactive API docs at /docs in a real headless Chromium with the network cut off.

Every request that is not to the local service is aborted, as on an air-gapped machine; Swagger UI
must still draw every operation of the service's OpenAPI document.
"""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest
from playwright.sync_api import Browser, Route, sync_playwright

from bench.dashboard_screenshot import DEBIAN_CHROMIUM, launch_chromium
from teacher_service.process import ServiceProcess

pytestmark = pytest.mark.skipif(not DEBIAN_CHROMIUM.exists(), reason="needs Debian's chromium (.ci/run installs it)")


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServiceProcess]:
    with ServiceProcess(tmp_path_factory.mktemp("docs") / "teacher.db") as teacher:
        yield teacher


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    with sync_playwright() as playwright:
        chromium = launch_chromium(playwright)
        yield chromium
        chromium.close()


def test_swagger_ui_draws_every_operation_with_no_network(service, browser):
    schema = httpx.get(f"{service.url}/openapi.json", timeout=10).json()
    operations = [(method.upper(), path) for path, item in schema["paths"].items() for method in item]

    page = browser.new_page()
    page.set_default_timeout(20_000)
    cut_off, failed, errors = [], [], []

    def only_the_service(route: Route) -> None:
        if route.request.url.startswith((service.url, "data:")):
            route.continue_()
        else:
            cut_off.append(route.request.url)
            route.abort("internetdisconnected")

    page.route("**/*", only_the_service)
    page.on("requestfailed", lambda request: failed.append(request.url))
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(f"{service.url}/docs")
    page.wait_for_selector(".opblock")

    drawn = page.eval_on_selector_all(
        ".opblock-summary",
        "blocks => blocks.map(b => [b.querySelector('.opblock-summary-method').textContent,"
        " b.querySelector('.opblock-summary-path').getAttribute('data-path')])",
    )
    assert sorted(tuple(block) for block in drawn) == sorted(operations)
    assert page.locator(".info .title").inner_text().startswith(schema["info"]["title"])
    assert cut_off == [] and failed == [] and errors == [], "the page needed nothing from outside the service"


def test_the_default_cdn_page_is_gone(service):
    assert httpx.get(f"{service.url}/redoc", timeout=10).status_code == 404
    page = httpx.get(f"{service.url}/docs", timeout=10).text
    assert "cdn" not in page and "https://" not in page
