"""The package's house rules, read from its imports with ``ast``: no module imports itself back
through others (no cycle), and no module imports one of a higher layer (docs/architecture.md
draws the layers). Every import counts: at the top of a module, inside a function, or under
``TYPE_CHECKING``."""

from __future__ import annotations

import ast
import fnmatch
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "socnav_wm"

LAYERS: tuple[tuple[str, ...], ...] = (
    # 0: the foundation, importing nothing of the project but each other
    (
        "socnav_wm",
        "socnav_wm.section",
        "socnav_wm.io",
        "socnav_wm.locks",
        "socnav_wm.progress",
        "socnav_wm.resources",
        "socnav_wm.devices",
        "socnav_wm.exports",
        "socnav_wm.layout",
        "socnav_wm.metrics",
    ),
    ("socnav_wm.env", "socnav_wm.env.*"),  # 1: the simulator
    ("socnav_wm.data", "socnav_wm.data.*"),  # 2: rollouts on disk
    ("socnav_wm.worldmodel", "socnav_wm.worldmodel.*"),  # 3: the learned models
    (  # 4: what acts in the simulator: agents, robots, planners
        "socnav_wm.agents",
        "socnav_wm.agents.*",
        "socnav_wm.planning",
        "socnav_wm.planning.*",
    ),
    ("socnav_wm.method_names", "socnav_wm.methods", "socnav_wm.methods.*"),  # 5: every method
    ("socnav_wm.evaluation", "socnav_wm.evaluation.*"),  # 6: paired tests, the report
    ("socnav_wm.studies.params",),  # 7: the studies' section, composed by the configuration
    ("socnav_wm.config",),  # 8: composes the sections, loads params.yaml
    ("socnav_wm.tracking", "socnav_wm.tracking_models"),  # 9: MLflow
    ("socnav_wm.stages", "socnav_wm.stages.*"),  # 10: one module per DVC stage
    ("socnav_wm.studies", "socnav_wm.studies.*", "socnav_wm.bench"),  # 11: grids, benchmarks
    ("socnav_wm.cli", "socnav_wm.cli.*"),  # 12: the command line
)
"""Layer by layer, bottom first: the modules of each (shell patterns over dotted names; the
first pattern that matches a module gives its layer). A module may import its own layer and
those below."""


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def _imports(path: Path, module: str, known: set[str]) -> set[str]:
    """The project's modules that ``path`` imports (``from a import b`` counts as ``a.b`` where
    that is a module, else ``a``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - (node.level - 1)]
                base = ".".join([*parts, base] if base else parts)
            names = [f"{base}.{alias.name}" for alias in node.names]
            names = [name if name in known else base for name in names]
        else:
            continue
        found.update(name for name in names if name in known and name != module)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    known = set(modules)
    return {name: _imports(path, name, known) for name, path in modules.items()}


def _layer(module: str) -> int:
    for index, patterns in enumerate(LAYERS):
        if any(fnmatch.fnmatchcase(module, pattern) for pattern in patterns):
            return index
    raise AssertionError(f"{module}: in no layer of tests/test_architecture.py's LAYERS")


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (its modules in order, the first repeated), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: finished
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_no_module_imports_itself_back() -> None:
    cycle = _cycle(_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_every_module_has_a_layer_and_imports_only_its_own_or_lower_ones() -> None:
    upward = [
        f"{module} (layer {_layer(module)}) imports {target} (layer {_layer(target)})"
        for module, targets in _graph().items()
        for target in sorted(targets)
        if _layer(target) > _layer(module)
    ]
    assert upward == []


@pytest.mark.parametrize(
    ("graph", "expected"),
    [
        ({"a": {"b"}, "b": {"c"}, "c": set()}, None),
        ({"a": {"b"}, "b": {"c"}, "c": {"a"}}, ["a", "b", "c", "a"]),
    ],
)
def test_the_cycle_finder_finds_cycles(graph: dict[str, set[str]], expected) -> None:
    assert _cycle(graph) == expected


def test_the_import_reader_sees_imports_inside_functions_and_relative_ones(tmp_path: Path) -> None:
    source = tmp_path / "mod.py"
    source.write_text(
        "from __future__ import annotations\n"
        "from . import b\n"
        "def f():\n"
        "    from socnav_wm.env.core import Simulator\n"
    )
    known = {"socnav_wm.env.core", "socnav_wm.env", "socnav_wm.x.b", "socnav_wm.x.mod"}
    assert _imports(source, "socnav_wm.x.mod", known) == {"socnav_wm.env.core", "socnav_wm.x.b"}
