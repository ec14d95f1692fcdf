"""The generated parts of the docs pages: the figures README.md and docs/USAGE.md quote, from
the results files, and USAGE's synopsis, from the walkthrough's parser (one source each).

A page quotes measured figures only inside a block between two markers that name a table here:

    <!-- figures: payoff -->
    ...the table and the command that measured it, generated...
    <!-- end figures -->

The synopsis sits between ``<!-- synopsis -->`` and ``<!-- end synopsis -->``: the parser's
``--help`` at a fixed width. ``python -m multigpu.studies.pages`` rewrites every such block from the files under
``docs/results/`` (``launch/experiments`` runs it after the experiments); tests/test_docs.py
fails where a block differs from what its file (or the parser) gives now, and where a page states a measured
figure outside a block, so the pages cannot drift from the results or from each other.
"""

from __future__ import annotations

import csv
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from multigpu.studies.prose import prose

ROOT = Path(__file__).resolve().parents[2]
#: the pages whose figures come from results files only
PAGES = ("README.md", "docs/USAGE.md")
BLOCK = re.compile(r"(<!-- figures: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- end figures -->)", re.S)


@dataclass(frozen=True)
class Table:
    """Rows of one results CSV as a Markdown table: ``columns`` are (CSV column, header,
    format); ``rows`` keeps the rows whose ``key`` is listed (all where empty); a key of several
    columns joins them with '+' (``scene+config``: rows named ``plant: full``)."""

    source: str
    command: str
    columns: tuple[tuple[str, str, str], ...]
    key: str = ""
    rows: tuple[str, ...] = ()
    note: str = ""

    def render(self, root: Path = ROOT) -> str:
        with open(root / self.source, newline="") as f:
            got = list(csv.DictReader(f))
        if self.rows:
            by = {": ".join(r[k] for k in self.key.split("+")): r for r in got}
            got = [by[k] for k in self.rows]
        head = "| " + " | ".join(h for _, h, _ in self.columns) + " |"
        rule = "|" + "|".join("---" if i == 0 else "---:" for i in range(len(self.columns))) + "|"
        body = ["| " + " | ".join(_cell(r[c], fmt) for c, _, fmt in self.columns) + " |" for r in got]
        note = f" {self.note}" if self.note else ""
        return "\n".join([head, rule, *body, "", f"Measured by `{self.command}` ({self.source}).{note}", ""])


def _cell(value: str, fmt: str) -> str:
    """A CSV value in ``fmt``: a number format where the value is one, else the value as written."""
    if "{:" not in fmt:
        return fmt.format(value)
    try:
        return fmt.format(float(value))
    except ValueError:
        return value


PAYOFF = ("multigpu experiment payoff --rounds 3", "docs/results/payoff/payoff_default.csv")
TABLES = {
    "payoff": Table(
        PAYOFF[1], PAYOFF[0],
        (("scene", "scene", "{}"), ("default_speedup", "default (`auto`) over `none`", "{:.2f}x"),
         ("best", "best strategy", "`{}`"), ("best_speedup", "best over `none`", "{:.2f}x"),
         ("of_best", "default / best", "{:.3f}"), ("paired_of_best", "paired by round", "{:.3f}"),
         ("ceiling", "ceiling over `none`", "{:.2f}x"), ("of_ceiling", "default / ceiling", "{:.2f}")),
        note=prose("pages", "payoff")),
    "walls": Table(
        "docs/results/walls/walls.csv", "multigpu experiment walls",
        (("scene", "scene", "{}"), ("grid", "wall", "{}"), ("balance", "balance", "`{}`"),
         ("efficiency", "render efficiency", "{:.0%}"), ("time_overlap", "time overlap", "{:.2f}"),
         ("imbalance", "imbalance", "{:.2f}"), ("triangle_overlap", "triangles drawn", "{:.2f}"),
         ("planned_overlap", "whole objects", "{:.2f}")),
        note=prose("pages", "walls")),
    "compare": Table(
        "docs/results/compare/compare.csv", "multigpu experiment compare",
        (("config", "decomposition", "{}"), ("emulated_fps", "emulated FPS", "{:.1f}"),
         ("imb_render", "render imbalance", "{:.2f}"), ("bytes_per_frame", "bytes sent per frame", "{:.0f}")),
        note=prose("pages", "compare")),
    "latency": Table(
        "docs/results/latency/latency.csv", "multigpu bench latency",
        (("scene", "scene", "{}"), ("latency", "`--latency`", "{}"), ("wall_ms", "wall ms per frame", "{:.1f}"),
         ("wall_cut", "cut against 0", "{:.0%}"), ("emulated_ms", "emulated frame ms", "{:.2f}"),
         ("input_to_photon_ms", "input to photon ms", "{:.1f}")),
        note=prose("pages", "latency")),
    "peer": Table(
        "docs/results/peer/peer.csv",
        "multigpu bench peer --model dragon_vrip.ply --split grid:8 --ranks 1,4 --out docs/results/peer",
        (("ranks", "ranks", "{}"), ("paraview_wall_ms", "ParaView + IceT wall ms", "{:.1f}"),
         ("multigpu_wall_ms", "multigpu wall ms", "{:.1f}"), ("wall_lead", "wall lead", "{:.2f}x"),
         ("paraview_cpu_ms", "ParaView CPU ms", "{:.1f}"), ("multigpu_cpu_ms", "multigpu CPU ms", "{:.1f}"),
         ("cpu_lead", "CPU lead", "{:.2f}x")),
        note=prose("pages", "peer")),
    "fidelity": Table(
        "docs/results/fidelity/fidelity.csv", "multigpu experiment fidelity",
        (("scene", "scene", "{}"), ("config", "frames", "{}"), ("frame_ms", "wall ms per frame", "{:.1f}"),
         ("speedup", "speedup", "{:.2f}x"), ("psnr_median", "PSNR median dB", "{:.1f}"),
         ("differ_share", "pixels differ", "{:.1%}"), ("within_band", "frames within 10 % of the target", "{:.0%}"),
         ("windowed_within_band", "10-frame windows within 10 %", "{:.0%}"),
         ("reduced_frames", "frames below full quality", "{}")),
        key="scene+config",
        rows=tuple(f"{s}: {c}" for s in ("plant", "city", "orbit", "large")
                   for c in ("full", "scale 0.5, lod 0 px", "scale 1, lod 4 px", "target 2x", "target 0.5x")),
        note=prose("pages", "fidelity")),
    "simplify": Table(
        "docs/results/simplify/simplify.csv",
        "multigpu bench simplify --model dragon_vrip.ply --out docs/results/simplify",
        (("mesh", "mesh", "{}"), ("library", "simplifier", "{}"), ("target", "triangles kept", "{:.4f}"),
         ("s_per_mtri", "s per M triangles", "{:.2f}"), ("hausdorff", "Hausdorff / diagonal", "{:.2e}"),
         ("mean_distance", "mean distance / diagonal", "{:.2e}")),
        note=prose("pages", "simplify")),
}


def render(name: str, root: Path = ROOT) -> str:
    """The generated body of block ``name`` (an error naming the block where no table has it)."""
    if name not in TABLES:
        raise KeyError(f"no figures table named '{name}' (known: {', '.join(TABLES)})")
    return TABLES[name].render(root)


def rewrite(text: str, root: Path = ROOT) -> str:
    """``text`` with every figures block regenerated."""
    return BLOCK.sub(lambda m: m.group(1) + render(m.group("name"), root) + m.group(4), text)


def blocks(text: str) -> list[tuple[str, str]]:
    """(name, body) of every figures block in ``text``."""
    return [(m.group("name"), m.group("body")) for m in BLOCK.finditer(text)]


def outside(text: str) -> str:
    """``text`` without its generated blocks and code blocks (what the figure check reads)."""
    text = SYNOPSIS.sub("", BLOCK.sub("", text))
    return re.sub(r"```.*?```", "", text, flags=re.S)


#: a measured figure in prose: a decimal with a unit or a ratio (1.27x, 5.9 %, 0.33 ms, 1.02 GB)
FIGURE = re.compile(r"(?<![\w.])\d+\.\d+\s?(?:x|ms|%|GB|MB|GiB|MiB|s|FPS)(?![\w])")


SYNOPSIS = re.compile(r"(<!-- synopsis -->\n)(?P<body>.*?)(<!-- end synopsis -->)", re.S)
#: the synopsis's width in columns (argparse wraps at the terminal's width otherwise)
WIDTH = 100


def synopsis() -> str:
    """``launch/walkthrough --help`` as the docs show it: the parser's help at ``WIDTH`` columns."""
    import os

    from multigpu.flags import walkthrough_parser

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(WIDTH)
    try:
        text = walkthrough_parser().format_help()
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old
    return f"```text\n$ launch/walkthrough --help\n{text}```\n"


def main(argv: list[str] | None = None) -> int:
    """Rewrite the generated blocks of ``PAGES`` (or the pages given): figures from the results
    files, the synopsis from the parser."""
    pages = [Path(p) for p in (argv if argv else [ROOT / p for p in PAGES])]
    for page in pages:
        old = page.read_text()
        new = SYNOPSIS.sub(lambda m: m.group(1) + synopsis() + m.group(3), rewrite(old))
        if new != old:
            page.write_text(new)
            print(f"figures: rewrote {page}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
