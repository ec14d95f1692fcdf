"""``multigpu bench timeline``: where each rank's wall time goes, frame by frame, drawn as a
timeline (Equalizer's statistics overlay in a picture): the same walk at ``--latency 0`` and
``--latency 1``, every rank's phases over the run's last frames (``--timeline``'s
timeline.json), one bar per phase, coloured by the component it counts in, labelled with its
frame. With frames in flight a rank's bars of frame f+1 (balancing, rendering) sit between
those of frame f (exchange, display): the gaps, its waits, shrink.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

#: phase -> (component, colour)
COMPONENT = {"input": ("load balancing", "#4c72b0"), "learn": ("load balancing", "#4c72b0"),
             "pose": ("load balancing", "#4c72b0"),
             "project": ("load balancing", "#4c72b0"), "choose": ("load balancing", "#4c72b0"),
             "plan": ("load balancing", "#4c72b0"),
             "animate": ("rendering", "#dd8452"), "cull": ("rendering", "#dd8452"),
             "render": ("rendering", "#dd8452"),
             "readback": ("rendering", "#dd8452"), "sync": ("synchronization", "#c44e52"),
             "exchange": ("frame exchange", "#55a868"), "display": ("display", "#8172b3"),
             "swap_wait": ("display", "#8172b3")}


def plot(timelines: dict[str, Path], png: Path) -> Path:
    """One panel per timeline.json (label -> file): ranks down, milliseconds across."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    docs = {label: json.loads(Path(p).read_text()) for label, p in timelines.items()}
    fig, axes = plt.subplots(len(docs), 1, figsize=(11, 1.2 + 0.9 * max(len(d["ranks"]) for d in docs.values())
                                                    * len(docs)), squeeze=False)
    for ax, (label, doc) in zip(axes[:, 0], docs.items()):
        for r, frames in enumerate(doc["ranks"]):  # ranks x frames x phases: a few hundred bars
            for fr in frames:
                for name, a, b in fr["phases"]:
                    ax.barh(r, b - a, left=a, height=0.7, color=COMPONENT.get(name, ("other", "#999999"))[1])
                if fr["phases"]:
                    a = min(p[1] for p in fr["phases"])
                    ax.text(a, r - 0.45, str(fr["frame"]), fontsize=6, va="bottom")
        ax.set_yticks(range(len(doc["ranks"])), [f"rank {r}" for r in range(len(doc["ranks"]))])
        ax.invert_yaxis()
        ax.set_title(label, fontsize=9, loc="left")
    axes[-1, 0].set_xlabel("ms (wall clock, from the earliest phase shown)")
    seen = {}
    for comp, colour in COMPONENT.values():
        seen.setdefault(comp, colour)
    fig.legend([plt.Rectangle((0, 0), 1, 1, color=c) for c in seen.values()], list(seen), loc="upper right",
               fontsize=7, ncol=len(seen))
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png


def bench_timeline(quick: bool, out: str = "out/timeline", scene: tuple[str, ...] = ("--scene", "plant"),
                   timeout: float = 900) -> Path:
    """Run the walk at each latency with ``--timeline`` on 4 ranks; plot both; print the file."""
    from multigpu.config import WalkConfig
    from multigpu.studies.runs import walk

    dest = Path(out)
    frames = 24 if quick else 120
    runs = {}
    for latency in (0, 1):
        run = dest / f"latency{latency}"
        flags = [*scene, "--frames", str(frames), "--latency", str(latency), "--timeline", "--mosaic-every", "0"]
        s = walk(run, WalkConfig.grid, WalkConfig.tile, flags, timeout, as_run=True).summary
        runs[f"--latency {latency}: {s['frame_ms']:.1f} ms a frame (wall), input to photon "
             f"{s['input_to_photon_ms']:.1f} ms"] = run / "timeline.json"
    png = plot(runs, dest / "timeline.png")
    print(f"timeline of the last frames, 4 ranks, {' '.join(scene)}: {png}")
    for label in runs:
        print(f"  {label}")
    sys.stdout.flush()
    return png
