"""Docs that run: every command line in README.md, docs/*.md, models/ and examples/ parses with the
real parser (``multigpu ...``, ``launch/walkthrough ...``, ``mpiexec ... -m multigpu ...``), a
walkthrough's flags pass the configuration's own checks where the files they name exist, and the
cheap ones (``scene info``, ``wall check``, ``tree``, ``--help``) run. In one process."""

import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

from multigpu.cli import build_parser, main
from multigpu.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", ROOT / "models" / "README.md", *sorted((ROOT / "docs").glob("*.md")),
         *sorted((ROOT / "examples").rglob("*.md"))]
START = re.compile(r"^(?:mpiexec -n \S+ (?:python -m mpi4py -m )?)?(multigpu|launch/walkthrough|python -m multigpu)\s")
#: words that stand for something the reader fills in: such a line is a template, not a command
PLACEHOLDERS = {"...", "K", "N", "F", "FILE", "ARGS", "NAME", "SCENE_OR_FILE", "RxC"}
#: flags whose value is a file the command reads
FILE_FLAGS = {"--model", "--wall", "--path", "--hostfile", "--head-poses"}
RUNS = (("scene", "info"), ("wall", "check"), ("tree",))


def commands(text: str) -> list[str]:
    """The command lines of a Markdown page: lines of code blocks and inline code spans that start
    like a command, without a trailing comment or description (two spaces, or ``#``)."""
    out, block = [], False
    for line in text.splitlines():
        if line.strip().startswith("```"):
            block = not block
            continue
        for c in [line.strip()] if block else re.findall(r"`([^`]+)`", line):
            c = re.split(r"\s{2,}|\s#\s", c)[0].strip()
            if START.match(c):
                out.append(c)
    return out


def argv_of(line: str) -> list[str] | None:
    """The arguments ``multigpu`` gets from a documented line; None for a template."""
    words = shlex.split(line)
    if PLACEHOLDERS & set(words) or any(c in line for c in "[]|<>"):  # a template or a synopsis
        return None
    if "-m" in words:  # mpiexec -n K python -m mpi4py -m multigpu ..., python -m multigpu ...
        at = len(words) - 1 - words[::-1].index("-m")
        if words[at + 1] != "multigpu":
            return None  # the launcher module: its own -n, then multigpu's arguments
        return words[at + 2:]
    if words[0] == "launch/walkthrough":
        return ["walkthrough", *words[1:]]
    return words[1:]


LINES = sorted({(p.relative_to(ROOT).as_posix(), c) for p in PAGES for c in commands(p.read_text())})


def test_the_docs_hold_commands():
    assert len(LINES) > 40 and any("launch/walkthrough" in c for _, c in LINES)


@pytest.mark.parametrize("page,line", LINES, ids=[f"{p}: {c}"[:90] for p, c in LINES])
def test_a_documented_command_parses(page, line, monkeypatch):
    argv = argv_of(line)
    if argv is None:
        pytest.skip("a template (a placeholder for the reader to fill)")
    monkeypatch.chdir(ROOT)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            args = build_parser().parse_args(argv)
        except SystemExit as exc:
            said = err.getvalue().strip().splitlines()[-1:]
            if exc.code != 0 and "arguments are required" in str(said):
                pytest.skip("the command's name in the prose (its arguments follow in the text)")
            assert exc.code == 0, f"{page}: `{line}` does not parse: {said}"
            return  # --help
    if args.cmd == "walkthrough":
        named = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a in FILE_FLAGS and argv[i + 1] != "interactive"]
        if all((ROOT / f).exists() for f in named):
            from multigpu.flags import walk_config

            try:
                walk_config(args)
            except InputError as exc:
                if "--hosts" not in str(exc) and "--hostfile" not in str(exc):  # the launcher's own flags
                    raise AssertionError(f"{page}: `{line}`: {exc}") from None


def _runnable(line: str) -> bool:
    """A cheap command (``RUNS``) with all its arguments (not the command's name in the prose)."""
    argv = argv_of(line)
    if not argv or not any(tuple(argv[:len(r)]) == r for r in RUNS):
        return False
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            build_parser().parse_args(argv)
    except SystemExit:
        return False
    return True


CHEAP = [(p, c) for p, c in LINES if _runnable(c)]


def test_some_documented_commands_are_cheap_enough_to_run():
    assert len(CHEAP) >= 3, CHEAP


@pytest.mark.parametrize("page,line", CHEAP, ids=[f"{p}: {c}"[:90] for p, c in CHEAP])
def test_a_cheap_documented_command_runs(page, line, monkeypatch, tmp_path):
    argv = argv_of(line)
    files = [a for a in argv[2:] if "." in a and not a.startswith("-")]
    if not all((ROOT / f).exists() for f in files):
        pytest.skip(f"names a file the reader brings: {files}")
    monkeypatch.chdir(ROOT)
    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path))
    if argv[:2] == ["wall", "check"] and "--offline" not in argv:
        argv = [*argv[:2], "--offline", *argv[2:]]
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(argv) == 0, f"{page}: `{line}` failed"
