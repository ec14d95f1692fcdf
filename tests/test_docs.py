"""The docs cite only files that exist in the repository."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", ROOT / "models" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
CITED = re.compile(r"(?<![\w/.-])((?:multigpu|tests|launch|docs|models|\.ci)/[\w./-]*\w)")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_cited_paths_exist(page):
    text = page.read_text()
    missing = []
    for path in set(CITED.findall(text)):
        if "*" in path or path.startswith("docs/results/") and "/" in path[len("docs/results/"):]:
            continue  # globs and per-run outputs (not in git)
        if not (ROOT / path).exists() and not (page.parent / path).exists():
            missing.append(path)
    links = [m for m in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", text) if not m.startswith("http")]
    missing += [m for m in links if not (page.parent / m).exists()]
    assert not missing, f"{page.name} cites missing files: {sorted(missing)}"


# -- generated parts of the pages (multigpu/studies/pages.py) -----------------------------------

def test_every_generated_block_is_what_its_source_gives_now():
    """Figures blocks equal their results file's table, USAGE's synopsis equals the parser's help:
    ``python -m multigpu.studies.pages`` regenerates them."""
    from multigpu.studies.pages import PAGES, SYNOPSIS, blocks, render, synopsis

    found = {}
    for rel in PAGES:
        text = (ROOT / rel).read_text()
        for name, body in blocks(text):
            assert body == render(name), f"{rel}: the '{name}' figures differ from their file (regenerate)"
            found.setdefault(rel, []).append(name)
        for m in SYNOPSIS.finditer(text):
            assert m.group("body") == synopsis(), f"{rel}: the synopsis differs from --help (regenerate)"
            found.setdefault(rel, []).append("synopsis")
    assert "payoff" in found["README.md"] and "synopsis" in found["docs/USAGE.md"], found


@pytest.mark.parametrize("rel", ["README.md", "docs/USAGE.md"])
def test_measured_figures_appear_only_in_generated_blocks(rel):
    """A decimal with a unit or a ratio in the prose would be a figure no file backs."""
    from multigpu.studies.pages import FIGURE, outside

    stray = FIGURE.findall(outside((ROOT / rel).read_text()))
    assert not stray, f"{rel} quotes figures outside generated blocks: {stray}"


def test_the_figure_check_can_fail():
    from multigpu.studies.pages import FIGURE, outside

    text = "It is 1.27x faster, 5.9 % of a frame, 0.33 ms.\n<!-- figures: payoff -->\n2.5x\n<!-- end figures -->\n"
    assert FIGURE.findall(outside(text)) == ["1.27x", "5.9 %", "0.33 ms"]
    assert FIGURE.findall("a 2x2 wall of 256x256 tiles, rank 0, --grid 3x3") == []


def test_the_synopsis_is_the_command_s_own_help():
    import argparse

    from multigpu.cli import build_parser
    from multigpu.flags import walkthrough_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert sub.choices["walkthrough"].format_help() == walkthrough_parser().format_help()


def test_walkthrough_help_groups_every_flag_shows_defaults_and_no_markup():
    from multigpu.flags import walkthrough_parser

    p = walkthrough_parser()
    groups = [g.title for g in p._action_groups if g._group_actions]
    for want in ("scene", "camera path", "wall and display", "balancing", "outputs", "run control"):
        assert want in groups, groups
    assert any(t.startswith("hosts") for t in groups), groups
    text = p.format_help()
    assert "``" not in text and "examples:" in text
    for action in p._actions:
        if not action.option_strings or action.dest == "help":
            continue
        assert action.help, f"{action.option_strings[0]} has no help"
        if action.default not in (None, False) and action.nargs != 0:  # a switch's default is its absence
            assert "default" in p._get_formatter()._get_help_string(action), action.option_strings[0]
