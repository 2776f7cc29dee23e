"""Layering: processors and shared packages never import the simulators (sim/ uses them, not the
other way round); only the CLI wires commands to simulators."""

from __future__ import annotations

import ast

from tests.conftest import ROOT

ALLOWED = ("trackctl/sim/", "trackctl/cli/")


def test_nothing_outside_sim_and_cli_imports_sim() -> None:
    offenders = []
    for path in sorted((ROOT / "trackctl").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith(ALLOWED):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            offenders += [f"{rel}: {n}" for n in names if n.startswith("trackctl.sim")]
    assert offenders == []


def test_library_code_never_prints_or_exits() -> None:
    offenders = []
    for path in sorted((ROOT / "trackctl").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith("trackctl/cli/"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                if node.func.id in ("print", "exit", "quit"):
                    offenders.append(f"{rel}:{node.lineno}: {node.func.id}()")
            if isinstance(node, ast.Attribute) and node.attr == "exit":
                if isinstance(node.value, ast.Name) and node.value.id == "sys":
                    offenders.append(f"{rel}:{node.lineno}: sys.exit")
    assert offenders == []


def _vmtrack_imports() -> dict[str, set[str]]:
    """Module -> the trackctl.vmtrack modules it imports (TYPE_CHECKING imports included: a
    cycle hidden from the interpreter is still one a reader must untangle)."""
    pkg = ROOT / "trackctl" / "vmtrack"
    mods = {p.stem for p in pkg.glob("*.py") if p.stem != "__init__"}
    graph: dict[str, set[str]] = {}
    for mod in sorted(mods):
        deps: set[str] = set()
        for node in ast.walk(ast.parse((pkg / f"{mod}.py").read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                if node.module.startswith("trackctl.vmtrack."):
                    deps.add(node.module.split(".")[2])
                elif node.module == "trackctl.vmtrack":
                    deps |= {a.name for a in node.names if a.name in mods}
        graph[mod] = deps - {mod}
    return graph


def test_vmtrack_has_no_import_cycle() -> None:
    graph = _vmtrack_imports()
    state: dict[str, int] = {}  # 1: on the path, 2: done
    cycles: list[list[str]] = []

    def visit(mod: str, path: list[str]) -> None:
        state[mod] = 1
        for dep in sorted(graph.get(mod, ())):
            if state.get(dep) == 1:
                cycles.append(path[path.index(dep) :] + [dep] if dep in path else [mod, dep])
            elif dep not in state:
                visit(dep, [*path, dep])
        state[mod] = 2

    for mod in sorted(graph):
        if mod not in state:
            visit(mod, [mod])
    assert cycles == []


def test_vmtrack_imports_no_private_name_across_modules() -> None:
    offenders = []
    for path in sorted((ROOT / "trackctl" / "vmtrack").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("trackctl."):
                offenders += [
                    f"{path.name}: {node.module}.{a.name}"
                    for a in node.names
                    if a.name.startswith("_")
                ]
    assert offenders == []
