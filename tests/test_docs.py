"""The documentation: the site builds with ``mkdocs build --strict`` (every link, page and anchor of
the navigation resolved), its reference parts are generated from the code, nothing in it is fetched
from the internet, and the README's front door says only true things (its commands, make targets,
links and paths exist). The results are one page per topic under docs/results/, BENCHMARKS.md a short
dated index into them; no heading runs over 120 characters, and every relative link of the README,
BENCHMARKS.md and the site lands on a file (and heading) that exists."""

from __future__ import annotations

import html
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import kuka_curriculum
from teacher_service.app import create_app
from teacher_service.core.config import Settings
from teacher_service.teachers import TEACHER_KINDS

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
README_MOST_LINES = 120
RESULTS = ROOT / "docs" / "results"
RESULTS_PAGES = {
    "index",
    "environment-speed",
    "training-speed",
    "service",
    "parity",
    "bakeoff-hard",
    "bakeoff-v0",
    "tune",
    "levels",
}
BENCHMARKS_MOST_LINES = 300
HEADING_MOST_CHARACTERS = 120
EXTERNAL_RESOURCE = re.compile(r"<(?:script|link|img|iframe)\b[^>]*\b(?:src|href)=\"(?:https?:)?//", re.IGNORECASE)
MARKDOWN_LINK = re.compile(r"\]\(([^)\s]+)\)")
TOP_FOLDERS = "bench|benchmarks|common|docs|examples|learner|models|rollout_worker|teacher_service|tests"
REPOSITORY_PATH = re.compile(rf"`((?:{TOP_FOLDERS})/[^`\s]*)`")


def _markdown_pages() -> list[Path]:
    """The Markdown a reader meets: the README, the benchmark index and every page of the site."""
    return [README, ROOT / "BENCHMARKS.md", *sorted((ROOT / "docs").rglob("*.md"))]


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("site")
    built = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(directory)],
        cwd=ROOT,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert built.returncode == 0, f"mkdocs build --strict failed:\n{built.stdout}\n{built.stderr}"
    return directory


def _text(page: Path) -> str:
    """A built page's visible text, tags removed and entities decoded."""
    return html.unescape(re.sub(r"<[^>]+>", "", page.read_text(encoding="utf-8")))


def test_the_commands_page_shows_every_commands_own_help(site: Path) -> None:
    page = _text(site / "commands" / "index.html")
    for command in kuka_curriculum.COMMANDS:
        assert f"usage: kuka-curriculum {command}" in page, f"no --help of {command!r} on the commands page"
    assert "<!-- reference" not in (site / "commands" / "index.html").read_text(encoding="utf-8")


def test_the_service_page_lists_every_setting_and_the_api_page_every_endpoint(site: Path) -> None:
    service = _text(site / "service" / "index.html")
    for name in Settings.model_fields:
        assert f"KC_{name.upper()}" in service
    api = _text(site / "api" / "index.html")
    for path, operations in create_app().openapi()["paths"].items():
        for method in operations:
            assert f"{method.upper()} {path}" in api, f"{method.upper()} {path} missing from the API page"


def test_the_concepts_page_lists_every_teacher_kind_with_its_parameters(site: Path) -> None:
    page = _text(site / "concepts" / "index.html")
    for kind, teacher in TEACHER_KINDS.items():
        assert kind in page
        for parameter in teacher.Params.model_fields:
            assert parameter in page, f"{kind}'s parameter {parameter!r} missing from the concepts page"


def test_the_results_pages_are_one_per_topic_and_show_only_figures_the_site_has(site: Path) -> None:
    pages = {page.stem for page in RESULTS.glob("*.md")}
    assert pages >= RESULTS_PAGES, f"docs/results/ lacks {sorted(RESULTS_PAGES - pages)}"
    for name in RESULTS_PAGES:
        page = site / "results" / ("" if name == "index" else name) / "index.html"
        for image in re.findall(r'<img[^>]*src="([^"]+)"', page.read_text(encoding="utf-8")):
            assert (page.parent / image).resolve().is_file(), f"results/{name}.md shows {image}, which the site lacks"


def _prose(markdown: str) -> str:
    """A page without its fenced code blocks, whose `#` lines are comments, not headings."""
    return re.sub(r"^```.*?^```", "", markdown, flags=re.MULTILINE | re.DOTALL)


def _headings(markdown: str) -> list[str]:
    return re.findall(r"^#{1,6} .*$", _prose(markdown), re.MULTILINE)


def test_no_heading_runs_over_120_characters() -> None:
    for page in _markdown_pages():
        for heading in _headings(page.read_text(encoding="utf-8")):
            assert len(heading) <= HEADING_MOST_CHARACTERS, (
                f"{page.relative_to(ROOT)} has a heading of {len(heading)} characters: {heading[:80]!r}..."
            )


def test_benchmarks_md_is_a_short_dated_index() -> None:
    lines = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= BENCHMARKS_MOST_LINES, (
        f"BENCHMARKS.md has {len(lines)} lines; the figures belong in docs/results/, one line each here"
    )


def _anchors(page: Path) -> set[str]:
    """The heading anchors MkDocs gives a page (its toc's slugs, the same text a reader sees)."""
    from markdown.extensions.toc import slugify

    anchors = set()
    for heading in _headings(page.read_text(encoding="utf-8")):
        text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.lstrip("#").strip())
        anchors.add(slugify(re.sub(r"[`*]", "", text), "-"))
    return anchors


def _link_target(page: Path, target: str) -> Path:
    """Where a relative link of a page lands. A docs page's ``benchmarks/`` links are served from the
    repository's ``benchmarks/`` by the site's hook, so they land there."""
    path = (page.parent / target).resolve()
    docs = ROOT / "docs"
    if not path.exists() and path.is_relative_to(docs) and path.relative_to(docs).parts[:1] == ("benchmarks",):
        return ROOT / path.relative_to(docs)
    return path


def test_every_relative_link_lands_on_a_file_and_heading_that_exist() -> None:
    for page in _markdown_pages():
        for target in MARKDOWN_LINK.findall(_prose(page.read_text(encoding="utf-8"))):
            if re.match(r"[a-z]+:", target):
                continue
            file, _, anchor = target.partition("#")
            landed = _link_target(page, file) if file else page
            where = f"{page.relative_to(ROOT)} links {target}"
            assert landed.exists(), f"{where}, which does not exist"
            # The site's own anchors (generated reference headings included) are MkDocs' to check.
            if anchor and landed.suffix == ".md" and not page.is_relative_to(ROOT / "docs"):
                assert anchor in _anchors(landed), f"{where}, but {landed.name} has no heading #{anchor}"


def test_nothing_is_fetched_from_the_internet_when_a_page_is_viewed(site: Path) -> None:
    for page in site.rglob("*.html"):
        fetched = EXTERNAL_RESOURCE.findall(page.read_text(encoding="utf-8"))
        assert not fetched, f"{page.relative_to(site)} loads {fetched} from the internet"


def test_the_readme_is_a_short_front_door() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MOST_LINES, f"README.md has {len(lines)} lines; the reference belongs in docs/"


def _code(markdown: str) -> str:
    """The text of a page's code blocks and inline code spans: what a reader would type."""
    blocks = re.findall(r"^```[^\n]*\n(.*?)^```", markdown, re.MULTILINE | re.DOTALL)
    spans = re.findall(r"`([^`\n]+)`", re.sub(r"^```.*?^```", "", markdown, flags=re.MULTILINE | re.DOTALL))
    return "\n".join(blocks + spans)


def test_the_readme_names_only_commands_and_make_targets_that_exist() -> None:
    code = _code(README.read_text(encoding="utf-8"))
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    targets = set(re.findall(r"^([A-Za-z][\w-]*):", makefile, re.MULTILINE))
    named = re.findall(r"\bmake ([a-z][\w-]*)", code)
    assert {"train", "test"} <= set(named), "the README's two commands are `make train` and `make test`"
    for target in named:
        assert target in targets, f"README.md runs `make {target}`, which the Makefile lacks"
    for command in re.findall(r"\bkuka-curriculum ([a-z][\w-]*)", code):
        assert command in kuka_curriculum.COMMANDS, f"README.md names `kuka-curriculum {command}`, which does not exist"


def test_the_readme_links_and_paths_exist() -> None:
    readme = README.read_text(encoding="utf-8")
    for target in MARKDOWN_LINK.findall(readme):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        assert (ROOT / target.split("#")[0]).exists(), f"README.md links {target}, which does not exist"
    for path in REPOSITORY_PATH.findall(readme):
        assert (ROOT / path.rstrip("/")).exists(), f"README.md names {path}, which does not exist"
