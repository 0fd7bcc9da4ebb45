"""The documentation: the site builds with ``mkdocs build --strict`` (every link, page and anchor of
the navigation resolved), its reference parts are generated from the code, nothing in it is fetched
from the internet, and the README's front door says only true things (its commands, make targets,
links and paths exist)."""

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
EXTERNAL_RESOURCE = re.compile(r"<(?:script|link|img|iframe)\b[^>]*\b(?:src|href)=\"(?:https?:)?//", re.IGNORECASE)
MARKDOWN_LINK = re.compile(r"\]\(([^)\s]+)\)")
TOP_FOLDERS = "bench|benchmarks|common|docs|examples|learner|models|rollout_worker|teacher_service|tests"
REPOSITORY_PATH = re.compile(rf"`((?:{TOP_FOLDERS})/[^`\s]*)`")


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


def test_the_benchmark_log_is_included_whole_with_its_figures(site: Path) -> None:
    page = site / "benchmarks" / "index.html"
    headings = re.findall(r"^#+ (.+)$", (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8"), re.MULTILINE)
    text = _text(page)
    last = re.sub(r"[`*]", "", headings[-1])
    assert last in text, f"BENCHMARKS.md's last heading {last!r} is not on the benchmark page"
    for image in re.findall(r'<img[^>]*src="([^"]+)"', page.read_text(encoding="utf-8")):
        assert (page.parent / image).resolve().is_file(), f"the benchmark page shows {image}, which the site lacks"


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
