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
               or m.startswith(("multigpu.gpu", "multigpu.rank", "multigpu.launcher", "multigpu.records",
                                   "multigpu.studies", "multigpu.cli"))}
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
            assert rel.parts[0] == "rank" or rel.name == "cli.py", f"{rel} imports mpi4py"


#: where code runs, told by its folder: each may not import the folders named here
APART = {"rank": ("multigpu.launcher",), "launcher": ("multigpu.rank",),
         "records": ("multigpu.rank", "multigpu.launcher", "mpi4py", "moderngl"),
         "panel": ("multigpu.rank", "multigpu.launcher", "mpi4py", "moderngl", "glfw")}


@pytest.mark.parametrize("sub", list(APART))
def test_rank_launcher_and_records_stay_apart(sub):
    """A rank's code (under MPI), the launcher's (never under MPI) and the records (neither)
    do not reach into one another; only the rank's side imports mpi4py (above)."""
    for f in _files(sub):
        bad = {m for m in _imports(f) if m.startswith(APART[sub])}
        assert not bad, f"{f.relative_to(PKG)} imports {bad}"


def test_modules_and_functions_stay_small():
    for f in _files():
        text = f.read_text()
        assert text.count("\n") <= 450, f"{f.relative_to(PKG)} has {text.count(chr(10))} lines"
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                assert n <= 80, f"{f.relative_to(PKG)}:{node.name} has {n} lines"


# -- the floor plan: imports run downward only (shared/LAYOUT.md) ---------------------------------

#: what each floor may import of the package besides itself; a unit not listed may import anything
#: below it that keeps the graph free of circles (checked next)
FLOORS = {
    "core": set(),
    "strategies": {"core"},
    "scene": {"core", "errors", "options"},  # options: each setting's flag, declared with its field
    "decompositions": {"core", "strategies"},
    "planner": {"core", "strategies", "decompositions"},
    "kernels": {"core", "strategies", "scene"},
}


def _module(path: Path) -> str:
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (top level or inside functions); ``from pkg
    import name`` counts as importing the submodule ``pkg.name`` where one exists, else ``pkg``."""
    files = {_module(f): f for f in _files()}
    graph = {}
    for name, f in files.items():
        deps = set()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                deps |= {a.name for a in node.names if a.name in files}
            elif isinstance(node, ast.ImportFrom) and node.module in files:
                subs = {f"{node.module}.{a.name}" for a in node.names} & files.keys()
                deps |= subs if len(subs) == len(node.names) else subs | {node.module}
        graph[name] = deps - {name}
    return graph


def _unit(module: str) -> str:
    """The floor a module stands on: its sub-package, or the top-level module's own name."""
    return module.split(".")[1] if "." in module else module


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan, iterative)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_each_floor_imports_only_the_floors_below():
    for module, deps in _graph().items():
        unit = _unit(module)
        if unit in FLOORS:
            bad = {d for d in deps if _unit(d) not in FLOORS[unit] | {unit}}
            assert not bad, f"{module} ({unit}/) imports {sorted(bad)}: above its floor"


def test_no_circles_between_packages():
    units: dict[str, set[str]] = {}
    for module, deps in _graph().items():
        units.setdefault(_unit(module), set()).update(_unit(d) for d in deps)
    for unit in units:
        units[unit].discard(unit)
    assert _cycles(units) == []


def test_no_circles_between_modules():
    """Not even through an import inside a function (a loop kept apart only by import order)."""
    assert _cycles(_graph()) == []


def test_the_cycle_finder_finds_one():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


#: blocking calls allowed, with why: the exit's one moment to leave at (every rank that gets there
#: is leaving with an error; MPICH's launcher kills those still finalizing otherwise), and the
#: heartbeat's receive of a message ``Iprobe`` has already found (it returns at once)
BLOCKING_ALLOWED = {("rank/job.py", "allreduce"), ("rank/job.py", "Recv")}
BLOCKING = ("Barrier", "Bcast", "bcast", "Gather", "gather", "Allgather", "allgather", "Allreduce", "allreduce",
            "Reduce", "reduce", "Scatter", "scatter", "Alltoall", "alltoall", "Recv", "recv", "Wait", "Waitall")


def test_every_wait_is_bounded():
    """No blocking MPI call in the package: every wait goes through ``exchange.wait_all`` (a peer
    that dies or hangs ends the job with a timeout, never freezes the wall)."""
    for f in _files():
        rel = f.relative_to(PKG).as_posix()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in BLOCKING:
                owner = ast.unparse(node.func.value)
                if "comm" in owner.lower() or "node" in owner or "MPI" in owner:
                    assert (rel, node.func.attr) in BLOCKING_ALLOWED, f"{rel}:{node.lineno} {owner}.{node.func.attr}()"


def test_exit_codes_come_from_one_place():
    """The job's exit codes live in ``exits.py``: no ``128 +`` elsewhere, no literal non-zero code
    returned or passed to an exit by the launcher, a rank or the entry point."""
    from multigpu import exits

    assert (exits.INTERRUPTED, exits.by_signal(15), exits.GAVE_UP, exits.BAD_INPUT) == (130, 143, 3, 2)
    for f in [*_files("launcher"), *_files("rank"), PKG / "cli.py"]:
        rel = f.relative_to(PKG).as_posix()
        for node in ast.walk(ast.parse(f.read_text())):
            assert not (isinstance(node, ast.BinOp) and 128 in [getattr(n, "value", None) for n in
                                                                (node.left, node.right)]), f"{rel}:{node.lineno} 128 +"
            value = None
            if isinstance(node, ast.Return) and isinstance(node.value, ast.Constant):
                value = node.value.value
            elif (isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) in
                  ("collective_exit", "exit", "_exit") and node.args and isinstance(node.args[0], ast.Constant)):
                value = node.args[0].value
            assert not (isinstance(value, int) and not isinstance(value, bool) and value in (1, 2, 3, 130)), \
                f"{rel}:{node.lineno} exits with a literal {value}"


def test_studies_start_jobs_through_the_one_launcher():
    """Every study's job goes through ``studies/runs.py`` (``walk``, ``job``, ``start``): no other
    study calls the MPI launcher's command or runner, or starts ``multigpu.launcher.mpirun``."""
    for f in _files("studies"):
        if f.name == "runs.py":
            continue
        text = f.read_text()
        needles = ("run_multigpu", ".command(", "multigpu.launcher.mpirun\", \"-n", "find_launcher", "killpg")
        for needle in needles if f.name != "simhosts.py" else needles[:-1]:  # it kills its namespaces' holders
            assert needle not in text, f"studies/{f.name} starts a job itself ({needle})"


def test_websockets_only_at_the_web_edge():
    for f in _files():
        rel = f.relative_to(PKG)
        if "websockets" in {m.split(".")[0] for m in _imports(f)}:
            assert rel.parts[0] in ("panel", "studies"), f"{rel} imports websockets"
