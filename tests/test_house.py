"""The house rules (docs/architecture.md), computed from the tree as it is.

Floors: common < twin < calib < scenarios < bench < pkm_calib (the one command), nothing
imports a floor above its own; no modules import each other in a circle (function-level imports
count: they run too); a source file stays within 450 lines and a folder within 20 modules;
every package's ``__init__`` names its public face (a docstring) and exports it (``__all__``);
the command line (calib.cli) and the scenarios reach another floor's subpackage through its
face, never through one of its modules. models/ stands apart: its generators are scripts no
floor imports.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parent.parent
FLOORS = {"common": 0, "twin": 1, "calib": 2, "scenarios": 3, "bench": 4, "pkm_calib": 5}
MAX_LINES = 450
MAX_MODULES = 20
# import other packages through their faces only
FACE_USERS = ("calib.cli", "scenarios", "pkm_calib")


def module_files(root: Path = ROOT) -> dict[str, Path]:
    """Every module of the floors, by dotted name (a package by its own name)."""
    out = {}
    for top in FLOORS:
        for path in sorted((root / top).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def imported_names(path: Path) -> set[str]:
    """Every dotted name an import statement of the file names, at any depth of the file."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{alias.name}" for alias in node.names)
    return out


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the modules of the floors it imports (a name that is no module is left out)."""
    return {
        m: {n for n in imported_names(p) if n in modules and n != m} for m, p in modules.items()
    }


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def upward(graph: dict[str, set[str]]) -> list[str]:
    """Imports of a module on a higher floor than the importer's."""
    floor = lambda m: FLOORS[m.split(".")[0]]  # noqa: E731
    return sorted(f"{m} -> {n}" for m, deps in graph.items() for n in deps if floor(n) > floor(m))


def packages(modules: dict[str, Path]) -> list[str]:
    return sorted(m for m, p in modules.items() if p.name == "__init__.py")


def deep_imports(graph: dict[str, set[str]], modules: dict[str, Path]) -> list[str]:
    """Imports from FACE_USERS of a module inside another package's subpackage (past its face)."""
    pkgs = set(packages(modules))
    bad = []
    for m, deps in graph.items():
        if not m.startswith(FACE_USERS):
            continue
        for n in deps:
            parent = n.rpartition(".")[0]
            own = m == parent or m.startswith(parent + ".")
            if n not in pkgs and parent in pkgs and parent.count(".") >= 1 and not own:
                if not parent.startswith("scenarios"):  # the scenarios' own rooms: free
                    bad.append(f"{m} -> {n}")
    return sorted(bad)


MODULES = module_files()
GRAPH = import_graph(MODULES)


def test_the_checks_can_fail():
    """The checks find what they look for in a made-up tree."""
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []
    assert upward({"twin.x": {"calib.y"}, "calib.y": {"twin.x"}}) == ["twin.x -> calib.y"]
    mods = {
        "calib.fit": Path("calib/fit/__init__.py"),
        "calib.fit.model": Path("calib/fit/model.py"),
        "scenarios.s": Path("scenarios/s.py"),
    }
    assert deep_imports({"scenarios.s": {"calib.fit.model"}}, mods) == [
        "scenarios.s -> calib.fit.model"
    ]
    assert deep_imports({"scenarios.s": {"calib.fit"}}, mods) == []


def test_the_floors_are_found():
    assert len(MODULES) > 150
    assert {m.split(".")[0] for m in MODULES} == set(FLOORS)


def test_no_import_circles():
    assert cycles(GRAPH) == []


def test_nothing_imports_upward():
    assert upward(GRAPH) == []


def test_models_stand_apart():
    assert not [m for m, deps in GRAPH.items() for n in imported_names(MODULES[m]) if n == "models"]


@pytest.mark.parametrize("top", sorted(FLOORS))
def test_files_within_450_lines(top):
    long = {
        str(p.relative_to(ROOT)): n
        for m, p in MODULES.items()
        if m.split(".")[0] == top and (n := len(p.read_text().splitlines())) > MAX_LINES
    }
    assert long == {}


def test_folders_within_20_modules():
    folders: dict[Path, int] = {}
    for p in MODULES.values():
        if p.name != "__init__.py":
            folders[p.parent] = folders.get(p.parent, 0) + 1
    crowded = {str(f.relative_to(ROOT)): n for f, n in folders.items() if n > MAX_MODULES}
    assert crowded == {}


def _names_all(node: ast.stmt) -> bool:
    targets = node.targets if isinstance(node, ast.Assign) else [getattr(node, "target", None)]
    return any(
        isinstance(n, ast.Name) and n.id == "__all__" for t in targets if t for n in ast.walk(t)
    )


def test_every_package_names_and_exports_its_face():
    faceless = []
    for name in packages(MODULES):
        tree = ast.parse(MODULES[name].read_text())
        exports = any(
            isinstance(node, (ast.Assign, ast.AnnAssign)) and _names_all(node) for node in tree.body
        )
        if not ast.get_docstring(tree) or not exports:
            faceless.append(name)
    assert faceless == []


@pytest.mark.parametrize("name", packages(MODULES))
def test_every_exported_name_is_there(name):
    """Each name a face exports resolves, and none is also one of its submodules' names (the
    submodule, once imported, would shadow it)."""
    package = importlib.import_module(name)
    submodules = {p.stem for p in MODULES[name].parent.glob("*.py")} | {
        p.name for p in MODULES[name].parent.iterdir() if (p / "__init__.py").is_file()
    }
    exported = set(package.__all__)
    for n in sorted(exported & submodules):  # a submodule listed as such
        assert isinstance(importlib.import_module(f"{name}.{n}"), ModuleType)
        assert isinstance(getattr(package, n), ModuleType), f"{name}.{n} is shadowed"
    for n in sorted(exported - submodules):
        getattr(package, n)  # raises AttributeError when the face names what is not there


def test_cli_and_scenarios_import_through_faces():
    assert deep_imports(GRAPH, MODULES) == []
