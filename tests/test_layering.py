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
