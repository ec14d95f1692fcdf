"""The package layout's rules (docs/ARCHITECTURE.md), checked: what may import what."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "multigpu"
PURE = ("core", "strategies", "scene", "decompositions")


def _imports(path: Path) -> set[str]:
    """Every module a file imports (top level or inside functions)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
    return out


def _files(sub: str | None = None):
    root = PKG / sub if sub else PKG
    return sorted(root.rglob("*.py"))


@pytest.mark.parametrize("sub", PURE)
def test_pure_packages_import_neither_gl_nor_mpi(sub):
    for f in _files(sub):
        bad = {m for m in _imports(f) if m.split(".")[0] in ("moderngl", "mpi4py", "glcontext")
               or m.startswith(("multigpu.gpu", "multigpu.parallel", "multigpu.studies", "multigpu.cli"))}
        assert not bad, f"{f.relative_to(PKG)} imports {bad}"


def test_pure_packages_load_without_gl_or_mpi():
    code = ("import sys, pkgutil, importlib, multigpu\n"
            "for sub in %r:\n"
            "    pkg = importlib.import_module('multigpu.' + sub)\n"
            "    for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):\n"
            "        importlib.import_module(m.name)\n"
            "print(sorted(k for k in sys.modules if k.split('.')[0] in ('moderngl', 'mpi4py')))" % (PURE,))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]"


def test_only_the_cli_reaches_into_the_studies():
    for f in _files():
        rel = f.relative_to(PKG)
        if rel.parts[0] == "studies" or rel.name == "cli.py":
            continue
        bad = {m for m in _imports(f) if m.startswith("multigpu.studies")}
        assert not bad, f"{rel} imports {bad}"


def test_gl_and_mpi_live_at_their_edges():
    for f in _files():
        rel = f.relative_to(PKG)
        mods = {m.split(".")[0] for m in _imports(f)}
        if "moderngl" in mods:
            assert rel.parts[0] in ("gpu", "display"), f"{rel} imports moderngl"
        if "glfw" in mods:
            assert rel.parts[0] == "display", f"{rel} imports glfw"
        if "mpi4py" in mods:
            assert rel.parts[0] == "parallel" or rel.name == "cli.py", f"{rel} imports mpi4py"


def test_modules_and_functions_stay_small():
    for f in _files():
        text = f.read_text()
        assert text.count("\n") <= 450, f"{f.relative_to(PKG)} has {text.count(chr(10))} lines"
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                assert n <= 80, f"{f.relative_to(PKG)}:{node.name} has {n} lines"
