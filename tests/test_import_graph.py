"""The house's import graph, read from the source: every arrow points down the design's layers, no
module imports by string, and every package says its one job.

Imports inside functions count too (the dispatcher loads each sub-command in one), so an arrow
cannot hide from this test by being deferred.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("common", "teacher_service", "rollout_worker", "learner")
DISPATCHER = "kuka_curriculum"

MAY_IMPORT: dict[str, set[str]] = {
    "common": {"common.kuka"},  # importing common registers the KUKA environments, as before the rooms
    "common.client": set(),
    "common.kuka": {"common.client"},
    "common.levels": {"common.client"},
    "common.families": {"common.client", "common.kuka", "common.levels", "common.policy"},
    "common.policy": {"common.client"},
    "teacher_service": {"common.client"},
    "rollout_worker": {"common.client", "common.families", "common.kuka", "common.policy"},
    "learner": {
        "common.client",
        "common.families",
        "common.kuka",
        "common.levels",
        "common.policy",
        "rollout_worker",
        "teacher_service",
    },
    DISPATCHER: {"common.kuka", "learner", "teacher_service"},
}
"""Each room and the rooms below it that it may use; a room may always use itself."""


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def room(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "common" and len(parts) > 1 else parts[0]


def sources() -> Iterator[Path]:
    for package in PACKAGES:
        yield from sorted((ROOT / package).rglob("*.py"))
    yield ROOT / f"{DISPATCHER}.py"


def first_party_imports(tree: ast.AST) -> Iterator[str]:
    """The first-party modules (or names in them) that a module imports, anywhere in its body."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [f"{node.module}.{alias.name}" for alias in node.names]
        else:
            continue
        yield from (name for name in names if name.split(".")[0] in (*PACKAGES, DISPATCHER))


def imports_by_string(tree: ast.AST) -> Iterator[str]:
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            called = ast.unparse(node.func)
            if called in ("importlib.import_module", "import_module", "__import__"):
                yield ast.unparse(node)


def test_every_import_points_down_the_layers():
    upward = []
    for path in sources():
        importer = module_name(path)
        for imported in first_party_imports(ast.parse(path.read_text())):
            source, target = room(importer), room(imported)
            if target != source and target not in MAY_IMPORT[source]:
                upward.append(f"{importer} imports {imported}")
    assert not upward, "imports against the layers:\n" + "\n".join(upward)


def test_no_module_imports_by_string():
    found = [
        f"{module_name(path)}: {call}" for path in sources() for call in imports_by_string(ast.parse(path.read_text()))
    ]
    assert not found, "imports by string:\n" + "\n".join(found)


@pytest.mark.parametrize("init", sorted(path for package in PACKAGES for path in (ROOT / package).rglob("__init__.py")))
def test_each_package_says_its_job(init: Path):
    docstring = ast.get_docstring(ast.parse(init.read_text()))
    assert docstring and len(docstring.split()) >= 5, f"{module_name(init)} needs a docstring that says its one job"


def module_paths() -> dict[str, Path]:
    return {module_name(path): path for path in sources()}


def imported_modules(importer: str, tree: ast.AST, modules: set[str]) -> set[str]:
    """The first-party modules ``importer`` uses: ``from package import module`` names the module, ``from module
    import name`` the module; the package ``__init__`` that every import passes through is not counted."""
    used = set()
    for name in first_party_imports(tree):
        while name and name not in modules:
            name = name.rpartition(".")[0]
        if name and name != importer:
            used.add(name)
    return used


def import_graph() -> dict[str, set[str]]:
    paths = module_paths()
    modules = set(paths)
    return {module: imported_modules(module, ast.parse(path.read_text()), modules) for module, path in paths.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each a cycle or a knot of them."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for target in sorted(graph.get(module, ())):
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in on_stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == module:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return found


def test_no_import_cycles_function_level_imports_included():
    assert not cycles(import_graph()), "modules that import each other, directly or around a loop"


def test_the_cycle_finder_finds_a_planted_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]


LEARNER_MAY_NOT_IMPORT = {
    "learner.core": ("learner.",),
    "learner": ("learner.experiments",),
}
"""Inside the learner: its core imports nothing else of the learner; the commands and the session around it
never import the experiments, which sit on top (only the dispatcher loads them)."""


def test_the_learner_core_stands_alone_and_only_the_dispatcher_loads_the_experiments():
    wrong = []
    for module, targets in import_graph().items():
        if not module.startswith("learner") or module.startswith("learner.experiments"):
            continue
        layer = "learner.core" if module.startswith("learner.core") else "learner"
        for target in targets:
            inside_core = layer == "learner.core" and target.startswith("learner.core")
            if not inside_core and target.startswith(LEARNER_MAY_NOT_IMPORT[layer]):
                wrong.append(f"{module} imports {target}")
    assert not wrong, "imports against the learner's layers:\n" + "\n".join(sorted(wrong))


SERVICE_LAUNCH = "teacher_service.process"
"""The one module of the teacher service the learner may import: what starting it as a child process needs.
The rest it learns from the service itself, over HTTP (``GET /api/v1/teachers``, a probe registration:
``learner.job.teacher_probe``), and from the client's schemas, as any client of a service deployed apart must."""


def test_the_learner_imports_of_the_service_only_what_starts_it():
    wrong = []
    for path in sources():
        importer = module_name(path)
        if room(importer) != "learner":
            continue
        for imported in first_party_imports(ast.parse(path.read_text())):
            launches = imported == SERVICE_LAUNCH or imported.startswith(f"{SERVICE_LAUNCH}.")
            if room(imported) == "teacher_service" and not launches:
                wrong.append(f"{importer} imports {imported}")
    assert not wrong, "the learner reaches into the service's internals:\n" + "\n".join(sorted(wrong))
