"""The live dashboard in a real headless Chromium against a real teacher service process.

The module starts ``kuka-curriculum serve`` on a free port with its own SQLite file; each test
feeds its own curriculum episodes over HTTP as rollout workers would, and reads back what the page
drew from Plotly's own trace data. The service guards writes with a token; the pages, which only
read, work without one. The ALP-GMM page's screenshot is saved to ``test-artifacts/dashboard.png``.
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from in_process_service import InProcessService
from playwright.sync_api import Browser, Error, Page, Playwright, sync_playwright

from bench.dashboard_screenshot import DEBIAN_CHROMIUM, launch_chromium
from common.client.schemas import API_PREFIX, ParameterSpec
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.process import ServiceProcess
from teacher_service.teachers import TEACHER_KINDS

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
SPACE = [ParameterSpec.from_parameter(p).model_dump() for p in KUKA_TASK_SPACE.parameters]
WRITE_TOKEN = "dashboard-test-token"
WRITES = {"Authorization": f"Bearer {WRITE_TOKEN}"}
FIT_RATE = 50
EPISODES = 3 * FIT_RATE
PAGE_TIMEOUT_MS = 20_000

pytestmark = pytest.mark.skipif(not DEBIAN_CHROMIUM.exists(), reason="needs Debian's chromium (.ci/run installs it)")


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServiceProcess]:
    """One service for the module; each test uses its own curriculum."""
    folder = tmp_path_factory.mktemp("teacher")
    with ServiceProcess(folder / "teacher.db", env={"KC_TEACHER_TOKEN": WRITE_TOKEN}) as teacher:
        yield teacher


@dataclass
class Chromium:
    """The module's Debian Chromium, launched anew when its browser process has died.

    A dead browser would otherwise fail every later test of the module with "Target page, context or
    browser has been closed", which hides where it died (CI, 2026-12-03: the first page's navigation, then
    20 more tests).
    """

    playwright: Playwright
    browser: Browser

    def new_page(self) -> Page:
        if not self.browser.is_connected():
            self.browser = launch_chromium(self.playwright)
        return self.browser.new_page(viewport={"width": 1400, "height": 900})


@pytest.fixture(scope="module")
def browser() -> Iterator[Chromium]:
    # pw:browser: Chromium's own stderr reaches the captured output of the test it dies in.
    with pytest.MonkeyPatch.context() as env:
        env.setenv("DEBUG", f"{os.environ.get('DEBUG', '')},pw:browser".lstrip(","))
        with sync_playwright() as playwright:
            chromium = Chromium(playwright, launch_chromium(playwright))
            yield chromium
            chromium.browser.close()


@dataclass
class PageProblems:
    """Everything a page did wrong: console errors, uncaught exceptions, failed or refused
    requests, and requests that left the service."""

    console: list[str] = field(default_factory=list)
    exceptions: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    http_errors: list[str] = field(default_factory=list)
    foreign: list[str] = field(default_factory=list)


def open_page(browser: Chromium, url: str, service: ServiceProcess, relaunches: int = 1) -> tuple[Page, PageProblems]:
    """``url`` in a new page that records its problems; opened once more in a new browser if the browser
    process (not the page: a crashed page fails the test) died on the way, as it did once on CI."""
    page = browser.new_page()
    page.set_default_timeout(PAGE_TIMEOUT_MS)
    problems = PageProblems()
    page.on("console", lambda message: message.type == "error" and problems.console.append(message.text))
    page.on("pageerror", lambda error: problems.exceptions.append(str(error)))
    page.on("requestfailed", lambda request: problems.failed.append(f"{request.url}: {request.failure}"))
    page.on(
        "response",
        lambda response: response.status >= 400 and problems.http_errors.append(f"{response.status} {response.url}"),
    )
    page.on(
        "request",
        lambda request: request.url.startswith((service.url, "data:")) or problems.foreign.append(request.url),
    )
    try:
        page.goto(url)
    except Error:  # the page, its context or the browser closed under it
        if browser.browser.is_connected() or relaunches == 0:
            raise
        warnings.warn(f"Chromium's browser process died opening {url}; opening it in a new browser", stacklevel=2)
        return open_page(browser, url, service, relaunches - 1)
    return page, problems


def create_curriculum(service: ServiceProcess, name: str, teacher: str, params: dict[str, Any]) -> None:
    body = {"teacher": teacher, "space": SPACE, "params": params, "seed": 3}
    response = httpx.put(f"{service.url}{API_PREFIX}/curricula/{name}", json=body, headers=WRITES, timeout=10)
    assert response.status_code == 201, response.text


def train(
    service: ServiceProcess, name: str, episodes: int, batch: int = FIT_RATE, settle: bool = True
) -> list[dict[str, Any]]:
    """Play ``episodes`` made-up episodes: easier tasks earn more, as for a real student. With
    ``settle``, each batch waits for the fits it caused."""
    rng = np.random.default_rng(7)
    played = []
    with httpx.Client(base_url=f"{service.url}{API_PREFIX}/curricula/{name}", headers=WRITES, timeout=10) as client:
        for _ in range(episodes // batch):
            tasks = client.post("/tasks", json={"count": batch}).raise_for_status().json()["tasks"]
            results = []
            for task in tasks:
                hardness = np.mean([_difficulty(p, task["params"][p["name"]]) for p in SPACE])
                reward = float(8.0 * (1.0 - hardness) - 2.0 + rng.normal(0.0, 0.5))
                results.append({"task_id": task["task_id"], "reward": reward, "success": reward > 3.0, "length": 80})
                played.append({"params": task["params"], "reward": reward})
            assert client.post("/results", json={"results": results}).raise_for_status().json()["accepted"] == batch
            if settle:
                wait_for_fits(service, name)
    return played


def _difficulty(parameter: dict[str, Any], value: float) -> float:
    easy, hard = parameter["easiest"], parameter["hardest"]
    return (value - easy) / (hard - easy)


def wait_for_fits(service: ServiceProcess, name: str) -> dict[str, Any]:
    """The curriculum's state once no fit is pending, so the next tasks come from the new model."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        state = httpx.get(f"{service.url}{API_PREFIX}/curricula/{name}/state", timeout=10).json()
        if state["curriculum"]["counters"]["fits_pending"] == 0:
            return state
        time.sleep(0.1)
    raise AssertionError(f"{name}: fits still pending after 60 s")


def traces(page: Page, plot_id: str) -> dict[str, list[dict[str, Any]]]:
    """The plot's Plotly traces grouped by their ``meta`` role."""
    data = page.evaluate(
        """id => (document.getElementById(id).data || []).map(t => ({
            meta: t.meta, name: t.name,
            x: Array.from(t.x || []), y: Array.from(t.y || []), z: t.z ? t.z.map(row => Array.from(row)) : null,
        }))""",
        plot_id,
    )
    grouped: dict[str, list[dict[str, Any]]] = {}
    for trace in data:
        grouped.setdefault(trace["meta"], []).append(trace)
    return grouped


def definitions(page: Page, selector: str) -> dict[str, str]:
    """A definition list's terms and values as shown."""
    box = page.locator(selector)
    return dict(zip(box.locator("dt").all_inner_texts(), box.locator("dd").all_inner_texts(), strict=True))


def select_dimensions(page: Page, x: str, y: str) -> None:
    page.select_option("#dim-x", x)
    page.select_option("#dim-y", y)


def assert_ellipses_match(ellipses: list[dict[str, Any]], components: list[dict[str, Any]], x: str, y: str) -> None:
    """Every drawn point lies on the 2-sigma contour of its component's (x, y) marginal."""
    names = [p["name"] for p in SPACE]
    i, j = names.index(x), names.index(y)
    assert len(ellipses) == len(components) >= 1
    for ellipse, component in zip(ellipses, components, strict=True):
        covariance = np.array(component["covariance"])[np.ix_([i, j], [i, j])]
        offsets = np.column_stack([ellipse["x"], ellipse["y"]]) - [component["mean"][x], component["mean"][y]]
        mahalanobis_sq = np.einsum("ni,ij,nj->n", offsets, np.linalg.inv(covariance), offsets)
        np.testing.assert_allclose(mahalanobis_sq, 4.0, rtol=1e-6)


def test_alp_gmm_dashboard_draws_the_posted_results_and_the_mixture(browser: Chromium, service: ServiceProcess) -> None:
    create_curriculum(service, "kuka-alp", "alp-gmm", {"fit_rate": FIT_RATE, "max_components": 4})
    played = train(service, "kuka-alp", EPISODES)
    state = wait_for_fits(service, "kuka-alp")
    components = state["teacher"]["components"]

    page, problems = open_page(browser, f"{service.url}/curricula/kuka-alp", service)
    page.wait_for_function(
        "() => (document.getElementById('space-plot').data || []).some(t => t.meta === 'tasks' && t.x.length > 0)"
    )
    assert page.inner_text("#kind") == "alp-gmm"
    assert page.inner_text("#stat-tasks") == page.inner_text("#stat-results") == str(EPISODES)
    assert page.inner_text("#stat-fits") == str(EPISODES // FIT_RATE)
    assert page.inner_text("#stat-refit").endswith("ago")
    assert definitions(page, "#params")["fit_rate"] == str(FIT_RATE)
    assert page.locator("#banner").is_hidden()

    progress = traces(page, "progress-plot")
    np.testing.assert_allclose(progress["rewards"][0]["y"], [episode["reward"] for episode in played])
    assert progress["rewards"][0]["x"] == list(range(1, EPISODES + 1))
    assert {"reward-mean", "success-rate"} <= set(progress)

    space = traces(page, "space-plot")
    np.testing.assert_allclose(space["tasks"][0]["x"], [e["params"]["rnd_obj_x"] for e in played])
    np.testing.assert_allclose(space["tasks"][0]["y"], [e["params"]["rnd_obj_y"] for e in played])
    assert_ellipses_match(space["ellipse"], components, "rnd_obj_x", "rnd_obj_y")
    np.testing.assert_allclose(traces(page, "alp-plot")["alp"][0]["y"], [c["mean_alp"] for c in components])

    select_dimensions(page, "jp2", "bias_obj_y")
    space = traces(page, "space-plot")
    np.testing.assert_allclose(space["tasks"][0]["x"], [e["params"]["jp2"] for e in played])
    np.testing.assert_allclose(space["tasks"][0]["y"], [e["params"]["bias_obj_y"] for e in played])
    assert_ellipses_match(space["ellipse"], components, "jp2", "bias_obj_y")
    assert page.locator("#space-plot .xtitle").text_content() == "jp2"
    assert page.locator("#space-plot .ytitle").text_content() == "bias_obj_y"

    strips = traces(page, "difficulty-plot")["difficulty"][0]
    assert strips["y"] == [p["name"] for p in SPACE]
    for parameter, shares in zip(SPACE, strips["z"], strict=True):
        values = [_difficulty(parameter, e["params"][parameter["name"]]) for e in played]
        expected, _ = np.histogram(np.clip(values, 0.0, 1.0), bins=len(shares), range=(0.0, 1.0))
        np.testing.assert_allclose(shares, expected / len(played), atol=1e-9)

    page.wait_for_timeout(3000)  # one more poll, which must redraw cleanly too
    ARTIFACTS.mkdir(exist_ok=True)
    select_dimensions(page, "rnd_obj_x", "rnd_obj_y")
    page.screenshot(path=ARTIFACTS / "dashboard.png", full_page=True)
    assert problems == PageProblems()
    page.close()


def test_curricula_page_links_to_a_manual_curriculum_showing_its_lesson(
    browser: Chromium, service: ServiceProcess
) -> None:
    create_curriculum(service, "kuka-manual", "manual", {"min_episodes": 10, "window": 10})
    train(service, "kuka-manual", 20, batch=10)
    teacher = httpx.get(f"{service.url}{API_PREFIX}/curricula/kuka-manual/state", timeout=10).json()["teacher"]

    page, problems = open_page(browser, f"{service.url}/", service)
    row = page.locator("#curricula-rows tr", has_text="kuka-manual")
    row.wait_for()
    assert "manual" in row.inner_text()
    row.get_by_role("link", name="kuka-manual").click()
    page.wait_for_url(f"{service.url}/curricula/kuka-manual")

    lesson = page.locator("#lesson")
    lesson.wait_for()
    assert f"Lesson {teacher['lesson'] + 1} of {teacher['lessons']}" in lesson.inner_text()
    shown = {name: float(value) for name, value in definitions(page, "#lesson").items()}
    assert shown == pytest.approx(teacher["lesson_params"], abs=1e-3)
    assert "measures no learning progress" in page.inner_text("#alp-empty")
    target = traces(page, "difficulty-plot")["difficulty-target"][0]
    np.testing.assert_allclose(target["x"], [_difficulty(p, teacher["lesson_params"][p["name"]]) for p in SPACE])
    assert problems == PageProblems()
    page.close()


def test_dashboard_survives_a_service_restart(browser: Chromium, service: ServiceProcess) -> None:
    create_curriculum(service, "kuka-restart", "random", {})
    train(service, "kuka-restart", FIT_RATE)
    page, problems = open_page(browser, f"{service.url}/curricula/kuka-restart", service)
    page.wait_for_function(f"() => document.getElementById('stat-results').textContent === '{FIT_RATE}'")
    page.evaluate("() => { window.sameDocument = true; }")

    service.stop()
    banner = page.locator("#banner")
    banner.wait_for(state="visible")
    assert "teacher unreachable" in banner.inner_text()
    assert page.inner_text("#stat-results") == str(FIT_RATE), "the last picture stays on screen"

    service.start()
    banner.wait_for(state="hidden")
    train(service, "kuka-restart", FIT_RATE)
    page.wait_for_function(f"() => document.getElementById('stat-results').textContent === '{2 * FIT_RATE}'")
    assert page.evaluate("() => window.sameDocument") is True, "the page was not reloaded"
    assert problems.exceptions == [] and problems.foreign == []
    page.close()


def test_fits_that_were_abandoned_or_superseded_are_listed_with_the_reason(browser: Chromium, tmp_path: Path) -> None:
    """Fits that take seconds against a 1 s limit, falling due faster than that: at most one runs
    and one waits, so some are superseded, and the last one is abandoned."""
    slow_fits = {"fit_rate": 1000, "min_components": 1, "max_components": 16, "nb_em_init": 5}
    env = {"KC_TEACHER_TOKEN": WRITE_TOKEN, "KC_FIT_TIMEOUT_S": "1"}
    with ServiceProcess(tmp_path / "teacher.db", env=env) as service:
        create_curriculum(service, "kuka-slow-fits", "alp-gmm", slow_fits)
        train(service, "kuka-slow-fits", 3000, batch=1000, settle=False)
        fits = wait_for_fits(service, "kuka-slow-fits")["fits"]
        assert [fit["index"] for fit in fits] == [0, 1, 2]
        assert fits[-1]["error"] == "abandoned after 1 s"
        assert any(fit["error"] == f"superseded by fit {fit['index'] + 1}" for fit in fits)

        page, problems = open_page(browser, f"{service.url}/curricula/kuka-slow-fits", service)
        rows = page.locator("#fit-rows tr")
        rows.nth(2).wait_for()
        for row, fit in zip(rows.all(), reversed(fits), strict=True):
            index, _, _, outcome = row.locator("td").all_inner_texts()
            assert index == str(fit["index"]), "newest first"
            assert outcome.startswith(f"{fit['error']}: ")
            if fit["error"].startswith("superseded"):
                assert outcome.endswith("the next fit fell due before this one could start, so this one was skipped")
                assert row.locator("td").nth(3).get_attribute("class") == "skipped"
            else:
                assert "it ran past the time limit (KC_FIT_TIMEOUT_S)" in outcome
                assert outcome.endswith("the teacher kept its model")
                assert row.locator("td").nth(3).get_attribute("class") == "failed"
        assert page.inner_text("#fits-note").endswith("3 not installed")
        assert page.locator("#fits-stopped").is_hidden()
        assert problems == PageProblems()
        page.close()


def test_a_full_disk_shows_a_banner_with_the_reason_until_writes_work_again(browser: Chromium, tmp_path: Path) -> None:
    with (
        InProcessService(tmp_path / "teacher.db") as service,
        httpx.Client(base_url=f"{service.url}{API_PREFIX}/curricula", timeout=10) as client,
    ):
        assert client.put("/full", json={"teacher": "random", "space": SPACE, "seed": 0}).status_code == 201
        page, problems = open_page(browser, f"{service.url}/curricula/full", service)
        banner = page.locator("#writes-failing")
        page.wait_for_function("() => document.getElementById('kind').textContent === 'random'")
        assert banner.is_hidden()

        service.fill_disk()
        assert client.post("/full/tasks", json={"count": 1024}).status_code == 503
        banner.wait_for(state="visible")
        assert "refuses writes: database or disk is full" in banner.inner_text()

        service.free_disk()
        assert client.post("/full/tasks", json={"count": 1024}).status_code == 200
        banner.wait_for(state="hidden")
        assert problems == PageProblems()
        page.close()


def assert_state_drawn(page: Page, teacher: dict[str, Any], x: str, y: str) -> None:
    """Whatever the teacher's state holds under the dashboard conventions is drawn on the (x, y)
    picker and in the teacher card, whichever kind it is."""
    space = traces(page, "space-plot")

    def rectangle(low: dict[str, float], high: dict[str, float]) -> tuple[list[float], list[float]]:
        return [low[x], high[x], high[x], low[x], low[x]], [low[y], low[y], high[y], high[y], low[y]]

    assert len(space.get("ellipse", [])) == len(teacher.get("components", []))
    assert len(space.get("region", [])) == len(teacher.get("regions", []))
    for trace, region in zip(space.get("region", []), teacher.get("regions", []), strict=True):
        xs, ys = rectangle(region["low"], region["high"])
        assert trace["x"] == pytest.approx(xs) and trace["y"] == pytest.approx(ys)
    if "bounds" in teacher:
        bounds = space["bounds"][0]
        xs, ys = rectangle(teacher["bounds"]["low"], teacher["bounds"]["high"])
        assert bounds["x"] == pytest.approx(xs) and bounds["y"] == pytest.approx(ys)
    if teacher.get("particles"):
        drawn = space["particles"][0]
        assert drawn["x"] == pytest.approx([p[x] for p in teacher["particles"]])
        assert drawn["y"] == pytest.approx([p[y] for p in teacher["particles"]])
    if teacher.get("pool"):
        drawn = space["pool"][0]
        assert drawn["x"] == pytest.approx([p[x] for p in teacher["pool"]])
        assert drawn["y"] == pytest.approx([p[y] for p in teacher["pool"]])
        colours = page.evaluate(
            "() => Array.from(document.getElementById('space-plot').data.find(t => t.meta === 'pool').marker.color)"
        )
        assert colours == pytest.approx(teacher["pool_learnability"]), "the pool is coloured by p(1 - p)"
    if "plan" in teacher:
        assert space["plan"][0]["x"] == pytest.approx([lesson[x] for lesson in teacher["plan"]])
        assert space["plan"][0]["y"] == pytest.approx([lesson[y] for lesson in teacher["plan"]])
    now = teacher.get("lesson_params", teacher.get("point"))
    if now is not None:
        assert (space["current-task"][0]["x"], space["current-task"][0]["y"]) == ([now[x]], [now[y]])
    moves = teacher.get("moves")
    assert page.locator("#moves-box").is_visible() == (moves is not None)
    if moves:
        rows = page.locator("#moves-rows tr").all_inner_texts()
        assert len(rows) == min(len(moves), 50)
        assert rows[0].split("\t")[-1] == moves[-1]["why"], "newest first"


BOX_KINDS = sorted(kind for kind, teacher in TEACHER_KINDS.items() if "float" in teacher.parameter_types)
LEVEL_KINDS = sorted(kind for kind, teacher in TEACHER_KINDS.items() if "integer" in teacher.parameter_types)


@pytest.mark.parametrize("kind", BOX_KINDS)
def test_every_kind_renders_its_own_state_with_no_console_error(
    browser: Chromium, service: ServiceProcess, kind: str
) -> None:
    name = f"kind-{kind}"
    create_curriculum(service, name, kind, {"fit_rate": FIT_RATE} if kind == "alp-gmm" else {})
    train(service, name, 2 * FIT_RATE)
    teacher = wait_for_fits(service, name)["teacher"]

    page, problems = open_page(browser, f"{service.url}/curricula/{name}", service)
    page.wait_for_function(
        "() => (document.getElementById('space-plot').data || []).some(t => t.meta === 'tasks' && t.x.length > 0)"
    )
    assert page.inner_text("#kind") == kind
    assert_state_drawn(page, teacher, "rnd_obj_x", "rnd_obj_y")
    shown = definitions(page, "#teacher-state")
    scalars = {k: v for k, v in teacher.items() if not isinstance(v, (dict, list))}
    assert set(shown) == set(scalars) - {"kind", "seed", "tasks_sampled", "results_seen"}
    select_dimensions(page, "jp2", "jp4")
    assert_state_drawn(page, teacher, "jp2", "jp4")
    page.wait_for_timeout(3000)  # one more poll, which must redraw cleanly too
    assert problems == PageProblems()
    page.close()


@pytest.mark.parametrize("kind", sorted(set(LEVEL_KINDS) - {"random", "fixed", "manual"}))
def test_a_level_kind_shows_its_likeliest_levels_with_no_console_error(
    browser: Chromium, service: ServiceProcess, kind: str
) -> None:
    name = f"levels-{kind}"
    space = [
        {"name": "seed", "type": "integer", "low": 0, "high": 59},
        {"name": "layout", "type": "integer", "low": 0, "high": 1},
    ]
    body = {"teacher": kind, "space": space, "params": {"update_every": 20} if kind != "plr" else {}, "seed": 3}
    with httpx.Client(base_url=f"{service.url}{API_PREFIX}/curricula", headers=WRITES, timeout=10) as client:
        assert client.put(f"/{name}", json=body).status_code == 201
        for _ in range(6):
            tasks = client.post(f"/{name}/tasks", json={"count": 40}).raise_for_status().json()["tasks"]
            results = [
                {
                    "task_id": t["task_id"],
                    "reward": 1.0,
                    "success": t["params"]["seed"] % 3 == 0,
                    "score": t["params"]["seed"] / 59,
                }
                for t in tasks
            ]
            client.post(f"/{name}/results", json={"results": results}).raise_for_status()
        teacher = client.get(f"/{name}/state").raise_for_status().json()["teacher"]

    page, problems = open_page(browser, f"{service.url}/curricula/{name}", service)
    page.wait_for_function("() => (document.getElementById('levels-plot').data || []).length > 0")
    bars = traces(page, "levels-plot")["levels"][0]
    assert bars["x"] == [f"#{row['level']}" for row in teacher["levels"]]
    assert bars["y"] == pytest.approx([row["probability"] for row in teacher["levels"]])
    assert bars["y"] == sorted(bars["y"], reverse=True), "the likeliest level first"
    assert page.inner_text("#levels-note") == "the 100 likeliest next of 120"
    assert definitions(page, "#teacher-state")["level_count"] == "120"
    page.wait_for_timeout(3000)  # one more poll, which must redraw cleanly too
    assert problems == PageProblems()
    page.close()


def test_a_space_of_one_level_parameter_shows_each_level_s_results_success_and_score(
    browser: Chromium, service: ServiceProcess
) -> None:
    """Issue 79: over levels 0 to 199 the task space drew the level against itself and the level bars had no
    numbers. Now each level played shows its recent results and success rate on its own axis, its score on
    hover, and the level bars are numbered."""
    space = [{"name": "level", "type": "integer", "low": 0, "high": 199}]
    with httpx.Client(base_url=f"{service.url}{API_PREFIX}/curricula", headers=WRITES, timeout=10) as client:
        assert client.put("/one-level", json={"teacher": "plr", "space": space, "seed": 1}).status_code == 201
        sent: list[dict[str, Any]] = []
        for _ in range(6):  # the sweep of 200 levels, then replays
            tasks = client.post("/one-level/tasks", json={"count": 40}).raise_for_status().json()["tasks"]
            results = [
                {"task_id": t["task_id"], "reward": 1.0, "success": t["params"]["level"] % 2 == 0, "score": 0.5}
                for t in tasks
            ]
            client.post("/one-level/results", json={"results": results}).raise_for_status()
            sent += [{**result, "level": task["params"]["level"]} for task, result in zip(tasks, results, strict=True)]
        teacher = client.get("/one-level/state").raise_for_status().json()["teacher"]

    page, problems = open_page(browser, f"{service.url}/curricula/one-level", service)
    page.wait_for_function("() => (document.getElementById('space-plot').data || []).length > 0")
    page.wait_for_function("() => (document.getElementById('levels-plot').data || []).length > 0")
    drawn = traces(page, "space-plot")
    levels = sorted({result["level"] for result in sent})
    bars, dots = drawn["level-results"][0], drawn["level-success"][0]
    assert bars["x"] == levels and dots["x"] == levels, "each level played, on the level's own axis"
    assert bars["y"] == [sum(result["level"] == level for result in sent) for level in levels]
    assert dots["y"] == [1.0 if level % 2 == 0 else 0.0 for level in levels]
    assert page.is_hidden("#dim-y"), "one parameter: nothing to plot it against"
    hover = page.evaluate("() => document.getElementById('space-plot').data[0].text")
    assert 0 in {row["level"] for row in teacher["levels"]}, "equal scores: the lowest level ranks first"
    assert hover[0].startswith("level 0<br>") and "success 100%" in hover[0] and "score 0.5" in hover[0]
    axis = page.evaluate("() => document.getElementById('levels-plot').layout.xaxis")
    assert axis.get("showticklabels", True) and axis["type"] == "category", "the level bars carry their numbers"
    bar_hover = page.evaluate("() => document.getElementById('levels-plot').data[0].text")
    assert all("recent results" in text for text in bar_hover)
    assert problems == PageProblems()
    page.close()


def test_a_lesson_plan_that_steps_back_shows_its_lessons_and_moves(browser: Chromium, service: ServiceProcess) -> None:
    space = [
        {"name": "gravity", "low": 2.0, "high": 12.0, "hardest": 12.0, "easiest": 2.0},
        {"name": "mass", "low": 0.5, "high": 1.5, "hardest": 1.5, "easiest": 0.5},
    ]
    params = {"steps": 4, "window": 4, "min_episodes": 4, "threshold": 5.0, "step_back_below": 1.0}
    body = {"teacher": "manual", "space": space, "params": params, "seed": 0}
    with httpx.Client(base_url=f"{service.url}{API_PREFIX}/curricula", headers=WRITES, timeout=10) as client:
        assert client.put("/plan-back", json=body).status_code == 201
        for reward in (6.0, 6.0, 0.0):
            tasks = client.post("/plan-back/tasks", json={"count": 4}).raise_for_status().json()["tasks"]
            results = [{"task_id": task["task_id"], "reward": reward} for task in tasks]
            client.post("/plan-back/results", json={"results": results}).raise_for_status()
        teacher = client.get("/plan-back/state").raise_for_status().json()["teacher"]
    assert [(m["from"], m["to"]) for m in teacher["moves"]] == [(0, 1), (1, 2), (2, 1)]

    page, problems = open_page(browser, f"{service.url}/curricula/plan-back", service)
    page.wait_for_function("() => (document.getElementById('moves-plot').data || []).length > 0")
    assert_state_drawn(page, teacher, "gravity", "mass")
    timeline = traces(page, "moves-plot")["moves"][0]
    assert (timeline["x"], timeline["y"]) == ([0, 4, 8, 12], [0, 1, 2, 1])
    assert page.inner_text("#moves-note") == "3 in all"
    assert "Lesson 2 of 4" in page.inner_text("#lesson")
    assert "back below 1" in page.inner_text("#lesson")
    assert definitions(page, "#teacher-state")["lesson"] == "1"
    assert problems == PageProblems()
    page.close()


def test_regions_bounds_and_particles_are_drawn_by_the_conventions(browser: Chromium, service: ServiceProcess) -> None:
    """The state entries that kinds on other branches publish (RIAC's regions, ADR's bounds,
    CURROT's particles, the learnability teacher's pool), handed to the page's own renderers as the
    conventions shape them."""
    create_curriculum(service, "conventions", "random", {})
    train(service, "conventions", 10, batch=10)
    page, problems = open_page(browser, f"{service.url}/curricula/conventions", service)
    page.wait_for_function(
        "() => (document.getElementById('space-plot').data || []).some(t => t.meta === 'tasks' && t.x.length > 0)"
    )
    low = {"a": 0.0, "b": 1.0}
    teacher = {
        "regions": [
            {"low": low, "high": {"a": 0.5, "b": 2.0}, "progress": 0.1, "results": 3},
            {"low": {"a": 0.5, "b": 1.0}, "high": {"a": 1.0, "b": 2.0}, "progress": -0.4, "results": 9},
        ],
        "bounds": {"low": low, "high": {"a": 0.25, "b": 1.5}, "low_boundary_probability": 0.5},
        "particles": [{"a": 0.1, "b": 1.1}, {"a": 0.2, "b": 1.9}],
        "particle_values": [1.0, 2.0],
        "pool": [{"a": 0.3, "b": 1.2}, {"a": 0.9, "b": 1.8}],
        "pool_success": [0.5, 0.9],
        "pool_learnability": [0.25, 0.09],
    }
    drawn = page.evaluate(
        """teacher => [...stateBackdrop(teacher, "a", "b"), ...stateMarks(teacher, "a", "b")].map(t => ({
            meta: t.meta, x: t.x, y: t.y, fill: t.fillcolor ?? null, colour: t.marker?.color ?? null,
            colourMax: t.marker?.cmax ?? null,
        }))""",
        teacher,
    )
    by_meta: dict[str, list[dict[str, Any]]] = {}
    for trace in drawn:
        by_meta.setdefault(trace["meta"], []).append(trace)
    assert [trace["x"] for trace in by_meta["region"]] == [[0.0, 0.5, 0.5, 0.0, 0.0], [0.5, 1.0, 1.0, 0.5, 0.5]]
    assert by_meta["region"][0]["y"] == [1.0, 1.0, 2.0, 2.0, 1.0]
    assert by_meta["region"][0]["fill"] != by_meta["region"][1]["fill"], "coloured by progress"
    assert by_meta["bounds"][0]["x"] == [0.0, 0.25, 0.25, 0.0, 0.0]
    assert by_meta["bounds"][0]["y"] == [1.0, 1.0, 1.5, 1.5, 1.0]
    assert (by_meta["particles"][0]["x"], by_meta["particles"][0]["y"]) == ([0.1, 0.2], [1.1, 1.9])
    pool = by_meta["pool"][0]
    assert (pool["x"], pool["y"]) == ([0.3, 0.9], [1.2, 1.8])
    assert (pool["colour"], pool["colourMax"]) == ([0.25, 0.09], 0.25), "p(1 - p) on its own scale, 0 to 0.25"
    assert problems == PageProblems()
    page.close()
