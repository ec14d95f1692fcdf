"""``multigpu bench floor``: the render imbalance a perfect balancer would still measure here.

Every rank renders exactly the same work (``rank/floor.py``, started under mpiexec), so
any imbalance it shows is this machine's measurement noise (ranks sharing cores, caches and
memory bandwidth): the floor under every strategy's ``imbalance_render_cpu``, and how much
noise alone inflates the slowest-rank (emulated) frame.
"""

from __future__ import annotations

import json
import sys

from multigpu.rank.floor import MARK
from multigpu.studies.tables import Columns

#: the scenes ``bench floor`` measures by default: name -> scene flags (as ``walkthrough`` takes them)
SCENES = {"plant": ["--scene", "plant"], "city": ["--scene", "city"]}


def run(scenes: dict[str, list[str]] | None = None, ranks: int = 4, frames: int = 120,
        timeout: float = 600, tile: int = 256, display: int | None = None) -> list[dict]:
    """Start the worker under mpiexec for each scene (name -> scene flags, and ``--path-kind``
    where not the walkthrough); the figures it printed, each with its ``scene`` name."""
    from multigpu.studies.runs import job as run_job
    from multigpu.studies.runs import study_env

    rows = []
    for name, flags in (scenes or SCENES).items():
        size = ["--tile", str(tile)] + ([] if display is None else ["--display", str(display)])
        job = run_job(ranks, ["bench", "floor", "--worker", *flags, "--frames", str(frames), *size], timeout,
                      env=study_env(), merge_stderr=True)
        lines = [ln for ln in job.stdout.splitlines() if ln.startswith(MARK)]
        if job.returncode != 0 or not lines:
            tail = "\n".join(job.stdout.strip().splitlines()[-5:])
            raise RuntimeError(f"bench floor: the MPI job failed (exit {job.returncode})\n{tail}")
        rows.append({**json.loads(lines[-1][len(MARK):]), "scene": name})
    return rows


def bench_floor(quick: bool, frames: int | None = None, ranks: list[int] | tuple[int, ...] = (4,), tile: int = 256,
                display: int | None = None) -> list[dict]:
    """Run the measurement on the plant and the city with each of ``ranks`` ranks, every rank the
    ``tile``-sided centre of a ``display``-sided display; print the table."""
    frames = frames or (20 if quick else 120)
    rows = [r for k in ranks for r in run(ranks=k, frames=frames, tile=tile, display=display)]
    side = 2 * tile if display is None else display
    print(f"identical work on every rank (the same {tile}x{tile} region of a {side}x{side} display, objects and "
          "camera), process CPU time per rank:")
    table = Columns(("scene", "scene", ">6"), ("ranks", "ranks", "5d"), ("frames", "frames", "6d"),
                    ("render_ms_mean", "render ms", "9.2f"), ("imbalance_floor", "imbalance floor", "15.3f"),
                    ("noise_cv", "noise c_v", "9.3f"))
    print(table.header())
    for r in rows:
        print(table.row(r))
    sys.stdout.flush()
    return rows
