"""The shape of the code: short functions, all errors in errors.py, SymPy only in codegen/."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "pige_sym"
MAX_LINES = 80


@functools.cache  # read and parsed once per run, not once per test
def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))  # the generated kernels too


@functools.cache
def _tree(path: Path) -> ast.Module:
    """A module's syntax tree, parsed once per run."""
    return ast.parse(path.read_text(encoding="utf-8"))


def _functions(path: Path) -> list[tuple[str, int]]:
    """(name, length in lines) of every function, its docstring included."""
    tree = _tree(path)
    return [(n.name, n.end_lineno - n.lineno + 1)  # type: ignore[operator]
            for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]


def test_no_function_is_longer_than_80_lines() -> None:
    long = [f"{p.relative_to(PACKAGE)}:{name} ({n} lines)" for p in _modules() for name, n in _functions(p)
            if n > MAX_LINES]
    assert not long, "split into named steps: " + ", ".join(long)


def test_every_exception_class_lives_in_errors_py() -> None:
    found = []
    for p in _modules():
        if p.name == "errors.py":
            continue
        for node in ast.walk(_tree(p)):
            if isinstance(node, ast.ClassDef) and any(
                isinstance(b, ast.Name) and (b.id.endswith(("Error", "Exception"))) for b in node.bases
            ):
                found.append(f"{p.relative_to(PACKAGE)}:{node.name}")
    assert not found, found


@pytest.mark.parametrize("path", [p for p in _modules() if "generated" not in p.parts],
                         ids=lambda p: str(p.relative_to(PACKAGE)))
def test_only_codegen_imports_sympy(path: Path) -> None:
    if "codegen" in path.parts:
        return
    for node in ast.walk(_tree(path)):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
            [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
        assert not any(n.split(".")[0] == "sympy" for n in names), f"{path} imports SymPy"
