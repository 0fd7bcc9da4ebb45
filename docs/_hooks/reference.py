"""MkDocs hook: the reference parts of the site, generated from the code they describe.

A page asks for one with a marker line, ``<!-- reference: NAME [ARGUMENT] -->``:

- ``help COMMAND``: ``kuka-curriculum COMMAND --help`` as the command prints it;
- ``help-others``: the help of every command the page has not shown yet, so a new command is
  documented the day it is added;
- ``settings``: the teacher service's ``KC_`` settings, their defaults, bounds and docs;
- ``teachers``: every teacher kind with its parameters, as ``GET /api/v1/teachers`` lists them;
- ``endpoints`` and ``schemas``: the service's OpenAPI schema as a reference.

Generating them means the site cannot drift from the command line or the service. Nothing here
touches the network. The hook also serves the repository's ``benchmarks/`` files that a page links
(the results pages' plots and tables) at the same path in the site, so they need no copy under ``docs/``.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import json
import os
import re
from functools import cache
from pathlib import Path
from typing import Any, Literal, get_args, get_origin

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File, Files
from mkdocs.structure.pages import Page

REPOSITORY = Path(__file__).resolve().parents[2]
MARKER = re.compile(r"^<!-- reference: (?P<name>[a-z-]+)(?: (?P<argument>\S+))? -->$", re.MULTILINE)
BENCHMARK_LINK = re.compile(r"\]\((?:\.\./)*(benchmarks/[^)\s#]+)\)")
HELP_COLUMNS = "100"


def on_files(files: Files, config: MkDocsConfig) -> Files:
    """Serve each ``benchmarks/`` file a page links."""
    sources = list(Path(config.docs_dir).rglob("*.md"))
    linked = {match for source in sources for match in BENCHMARK_LINK.findall(source.read_text(encoding="utf-8"))}
    for path in sorted(linked):
        if (REPOSITORY / path).is_file() and files.get_file_from_path(path) is None:
            files.append(File(path, str(REPOSITORY), config.site_dir, config.use_directory_urls))
    return files


def on_page_markdown(markdown: str, page: Page, config: MkDocsConfig, files: Files) -> str:
    shown: set[str] = set()

    def expand(match: re.Match[str]) -> str:
        name, argument = match["name"], match["argument"]
        if name == "help" and argument:
            shown.add(argument)
            return _help(argument)
        if name == "help-others" and not argument:
            return "\n\n".join(f"## `{command}`\n\n{_help(command)}" for command in _commands() if command not in shown)
        generated = {"settings": _settings, "teachers": _teachers, "endpoints": _endpoints, "schemas": _schemas}
        if name in generated and not argument:
            return generated[name]()
        raise PluginError(f"{page.file.src_uri}: unknown reference marker {match[0]!r}")

    return MARKER.sub(expand, markdown)


def _commands() -> list[str]:
    import kuka_curriculum

    return list(kuka_curriculum.COMMANDS)


@cache
def _help(command: str) -> str:
    """The command's ``--help``, wrapped at a fixed width whatever the terminal."""
    import kuka_curriculum

    if command not in kuka_curriculum.COMMANDS:
        raise PluginError(f"no kuka-curriculum command {command!r}; there are {sorted(kuka_curriculum.COMMANDS)}")
    output = io.StringIO()
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = HELP_COLUMNS
    try:
        with contextlib.redirect_stdout(output), contextlib.suppress(SystemExit):
            kuka_curriculum.main([command, "--help"])
    finally:
        if previous is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = previous
    return f"```text\n{output.getvalue().rstrip()}\n```"


def _cell(text: Any) -> str:
    """A value as one Markdown table cell."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _number(value: Any) -> str:
    """A bound as a person writes it: 2, not 2.0 (JSON schemas write integer bounds as floats)."""
    return str(int(value)) if isinstance(value, float) and value.is_integer() else str(value)


BOUND_SYMBOLS = {
    "ge": "≥",
    "minimum": "≥",
    "gt": ">",
    "exclusiveMinimum": ">",
    "le": "≤",
    "maximum": "≤",
    "lt": "<",
    "exclusiveMaximum": "<",
    "min_length": "length ≥",
    "minLength": "length ≥",
    "max_length": "length ≤",
    "maxLength": "length ≤",
    "minItems": "items ≥",
    "maxItems": "items ≤",
    "maxProperties": "entries ≤",
}


def _bounds(metadata: list[Any]) -> str:
    """A settings field's bounds, from its pydantic constraint objects."""
    return ", ".join(
        f"{symbol} {_number(getattr(item, name))}"
        for item in metadata
        for name, symbol in BOUND_SYMBOLS.items()
        if getattr(item, name, None) is not None
    )


def _settings() -> str:
    from teacher_service.core.config import Settings

    prefix = Settings.model_config.get("env_prefix", "")
    rows = ["| variable | default | bounds | what it does |", "|---|---|---|---|"]
    for name, field in Settings.model_fields.items():
        default = "none" if field.default is None else f"`{field.default}`"
        choices = get_args(field.annotation) if get_origin(field.annotation) is Literal else ()
        bounds = _bounds(field.metadata) or (("one of " + ", ".join(f"`{c}`" for c in choices)) if choices else "")
        rows.append(f"| `{prefix}{name.upper()}` | {default} | {_cell(bounds)} | {_cell(field.description or '')} |")
    return "\n".join(rows)


def _teachers() -> str:
    from teacher_service.api.routes.teachers import describe_kind
    from teacher_service.teachers import TEACHER_KINDS

    sections = []
    for kind, teacher in sorted(TEACHER_KINDS.items()):
        info = describe_kind(kind, teacher)
        rows = ["| parameter | type | default | bounds | what it does |", "|---|---|---|---|---|"]
        for parameter in info.parameters:
            bounds = [
                f"{symbol} {_number(value)}"
                for symbol, value in (
                    ("≥", parameter.minimum),
                    (">", parameter.exclusive_minimum),
                    ("≤", parameter.maximum),
                    ("<", parameter.exclusive_maximum),
                    ("items ≤", parameter.max_items),
                )
                if value is not None
            ]
            if parameter.choices:
                bounds.append("one of " + ", ".join(f"`{choice}`" for choice in parameter.choices))
            rows.append(
                f"| `{parameter.name}` | {_cell(parameter.type)} | `{_cell(json.dumps(parameter.default))}` "
                f"| {_cell(', '.join(bounds))} | {_cell(parameter.doc)} |"
            )
        table = "\n".join(rows) if info.parameters else "No parameters."
        sections.append(f"### `{kind}`\n\n{_describe(info.summary, teacher)}\n\n{table}")
    return "\n\n".join(sections)


def _describe(summary: str, teacher: type) -> str:
    """A kind's summary; one that points to its module's docstring gets that docstring's opening."""
    if "(see the module docstring)" not in summary:
        return summary
    module = inspect.getmodule(teacher)
    paragraphs = inspect.cleandoc((module.__doc__ if module else None) or "").split("\n\n")
    return "\n\n".join(paragraphs[:2]).replace("``", "`")


@cache
def _openapi() -> dict[str, Any]:
    from teacher_service.app import create_app

    schema: dict[str, Any] = create_app().openapi()
    return schema


def _type(schema: dict[str, Any]) -> str:
    """A schema's type in a few words, naming referenced models as links to their section."""
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#{name.lower()})"
    for union in ("anyOf", "oneOf"):
        if union in schema:
            return " or ".join(_type(branch) for branch in schema[union])
    if schema.get("type") == "array":
        return f"array of {_type(schema.get('items', {}))}"
    if "enum" in schema:
        return " or ".join(f"`{json.dumps(value)}`" for value in schema["enum"])
    if "const" in schema:
        return f"`{json.dumps(schema['const'])}`"
    if schema.get("type") == "object" and isinstance(schema.get("additionalProperties"), dict):
        return f"object of {_type(schema['additionalProperties'])}"
    return str(schema.get("type", "any"))


def _constraints(schema: dict[str, Any]) -> str:
    """A field's default and bounds, gathered from every branch of a union."""
    branches = [schema, *schema.get("anyOf", []), *schema.get("oneOf", [])]
    parts = [f"default `{json.dumps(schema['default'])}`"] if "default" in schema else []
    symbols = BOUND_SYMBOLS.items()
    parts += [f"{symbol} {_number(branch[key])}" for branch in branches for key, symbol in symbols if key in branch]
    parts += [f"matches `{branch['pattern']}`" for branch in branches if "pattern" in branch]
    return ", ".join(parts)


def _sentence(text: str) -> str:
    return _cell(text).rstrip(".")


def _endpoints() -> str:
    sections = []
    for path, operations in _openapi()["paths"].items():
        for method, operation in operations.items():
            lines = [f"### `{method.upper()} {path}`", "", inspect.cleandoc(operation.get("description", ""))]
            parameters = operation.get("parameters", [])
            if parameters:
                lines += ["", "| parameter | in | type | required | bounds | what it is |", "|---|---|---|---|---|---|"]
                lines += [
                    f"| `{p['name']}` | {p['in']} | {_cell(_type(p.get('schema', {})))} | "
                    f"{'yes' if p.get('required') else 'no'} | {_cell(_constraints(p.get('schema', {})))} "
                    f"| {_cell(p.get('description', ''))} |"
                    for p in parameters
                ]
            body = operation.get("requestBody", {}).get("content", {}).get("application/json")
            if body:
                lines += ["", f"Request body (JSON): {_type(body['schema'])}."]
            lines += ["", "| status | when | body |", "|---|---|---|"]
            for code, response in operation.get("responses", {}).items():
                content = response.get("content", {})
                if "application/json" in content:
                    answer = _type(content["application/json"].get("schema", {}))
                else:
                    answer = ", ".join(content) or "none"
                lines.append(f"| {code} | {_sentence(response.get('description', ''))} | {_cell(answer)} |")
            sections.append("\n".join(lines))
    return "\n\n".join(sections)


def _schemas() -> str:
    sections = []
    for name, schema in sorted(_openapi()["components"]["schemas"].items()):
        lines = [f"### {name}", "", inspect.cleandoc(schema.get("description", "")).replace("``", "`")]
        properties = schema.get("properties", {})
        if properties:
            required = set(schema.get("required", []))
            lines += ["", "| field | type | required | default and bounds | what it is |", "|---|---|---|---|---|"]
            lines += [
                f"| `{field}` | {_cell(_type(value))} | {'yes' if field in required else 'no'} "
                f"| {_cell(_constraints(value))} | {_cell(value.get('description', ''))} |"
                for field, value in properties.items()
            ]
        sections.append("\n".join(lines))
    return "\n\n".join(sections)
