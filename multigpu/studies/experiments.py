"""The paper's evaluation (Section 7) as runnable experiments: ``multigpu experiment NAME``.

Each experiment launches walkthrough jobs (``mpiexec -n K ... multigpu walkthrough``, each
under a hard timeout) or, for ``overlap``, runs the balancer in process, then writes into
``OUT/NAME/``: ``NAME.csv`` (one row per configuration), PNG plots (matplotlib) and
``NAME.md``, a Markdown fragment with the table and the plots. ``all`` runs every experiment
and joins the fragments into one results page.

Figures and what they are (see records/report.py): component columns are wall-clock means per rank;
"emulated" figures use each rank's process CPU time and take the slowest rank per frame, the
frame time the run would have with one core (GPU) per rank. Ranks outnumber cores here, so
speedups and efficiencies are computed from emulated figures only.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from multigpu.errors import InputError
from multigpu.studies.prose import prose
from multigpu.studies.registry import EXPERIMENTS as NAMES
from multigpu.studies.registry import load
from multigpu.studies.runs import PAPER, Settings

#: every experiment by name (``registry.py`` names them; their modules load here)
EXPERIMENTS = {name: load(where) for name, where in NAMES.items()}


def run(name: str, out: Path, quick: bool = False, results: Path | None = None, rounds: int | None = None) -> int:
    """Run one experiment (or ``all``) into ``out``; ``all`` also writes the results page.
    ``rounds``: alternated rounds of the experiments that repeat runs (None: their own numbers)."""
    if name != "all" and name not in EXPERIMENTS:
        raise InputError(f"experiment: unknown experiment '{name}' (known: all, {', '.join(EXPERIMENTS)})")
    s = Settings.make(quick, rounds)
    names = list(EXPERIMENTS) if name == "all" else [name]
    out = Path(out)
    sections = []
    t_all = time.perf_counter()
    for n in names:
        d = out / n
        d.mkdir(parents=True, exist_ok=True)
        t = time.perf_counter()
        print(f"experiment {n} ...", flush=True)
        md = EXPERIMENTS[n](s, d)
        dt = time.perf_counter() - t
        how = f" (`--rounds {s.rounds}`)" if s.rounds else ""  # a rerun with other rounds says so
        md = f"## {n}\n\n{md}\n\n_{dt:.0f} s wall for this experiment{how}._\n"
        (d / f"{n}.md").write_text(md)
        sections.append((n, md))
        print(f"experiment {n}: {dt:.0f} s, outputs in {d}/", flush=True)
    if name == "all":
        page = Path(results) if results else out / "RESULTS.md"
        page.parent.mkdir(parents=True, exist_ok=True)
        page.write_text(_results_page(sections, out, page, s, time.perf_counter() - t_all))
        print(f"results page: {page}")
    elif results and Path(results).is_file():  # one experiment rerun: replace its section in place
        page = Path(results)
        page.write_text(_replace_section(page.read_text(), name, _relink(sections[0][1], out, page, name)))
        print(f"results page: {page} (section {name} replaced)")
    return 0


def _relink(md: str, out: Path, page: Path, name: str) -> str:
    """A fragment's image links, relative to OUT/NAME/, made relative to the results page."""
    rel = os.path.relpath(out, page.parent)
    return md.replace("](", f"]({rel}/{name}/").replace(f"]({rel}/{name}/http", "](http")


def _replace_section(text: str, name: str, section: str) -> str:
    """``text`` with its ``## name`` section (up to the next ``## ``) replaced, or appended."""
    head = f"## {name}\n"
    start = text.find(head)
    if start < 0:
        return text.rstrip() + "\n\n" + section
    end = text.find("\n## ", start + len(head))
    return text[:start] + section.rstrip() + "\n" + (text[end:] if end >= 0 else "")


def _results_page(sections, out: Path, page: Path, s: Settings, seconds: float) -> str:
    import platform

    body = [_relink(md, out, page, n) for n, md in sections]  # links in fragments are relative to OUT/NAME/
    cmd = "launch/experiments" + (" --quick" if s.quick else "")
    return prose("experiments", "page", cmd=cmd, minutes=seconds / 60, machine=platform.machine(),
                 cores=os.cpu_count(), python=platform.python_version(), paper_mtris=PAPER["triangles"] / 1e6,
                 triangles=s.triangles, scaled=PAPER["triangles"] / s.triangles, sections="\n".join(body))
