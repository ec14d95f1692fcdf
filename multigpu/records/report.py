"""Timing rows to the paper's Table 1 breakdown. Pure numpy: no MPI, no GL.

Figures and what they are:
* component columns ``*_ms`` are wall-clock times per rank per frame (``time.perf_counter``);
* ``*_cpu_ms`` are the same phases as process CPU time (``time.process_time``), which stays
  honest when ranks outnumber cores;
* ``emulated_frame_ms`` is the emulated parallel frame time: per frame, the slowest rank's CPU
  time for load balancing + rendering + exchange + display, i.e. the frame time the run would
  have with one core (GPU) per rank; ``balancing_share`` the mean rank's load balancing and
  culling CPU over it (means over frames);
* presenting (``--present window``): ``present_ms`` is a rank's upload + blit + swap (wall),
  ``swap_wait_ms`` its wait in the swap barrier, ``swap_ms`` the moment its swap returned,
  after the frame's earliest swap (one clock per host), and ``swap_skew_ms`` the frame's latest
  minus earliest swap return (the same on every row of a frame; 0 when headless);
* ``input_ms``: the frame's input phase (rank 0 reads keys and mouse, the camera and commands
  reach every rank in one broadcast; 0 when headless); ``balance``: the strategy (screen) or
  decomposition that planned the frame, by name (it may change at a key press);
* ``learning_cpu_ms``, ``posing_cpu_ms``, ``projection_cpu_ms``, ``choosing_cpu_ms``,
  ``planning_cpu_ms``: the load balancing CPU time in its five phases (they add up to
  ``load_balancing_cpu_ms``): the strategy learning from the last frame's measured times, posing
  a moving scene's objects' bounds at the frame's scene time (where its motion put them; 0 where
  nothing moves), projecting the object bounds (``--projection
  shared``: this rank's slice), choosing the frame's quality (render scale, levels of detail),
  planning the partition (``--partition broadcast``: with its broadcast);
* ``animating_cpu_ms``: a moving scene's own work, a part of ``rendering_cpu_ms``: where its
  motion puts every object at the frame's scene time, and their maps sent to the GL;
* ``render_scale``, ``lod_error_px``: the frame's quality (``--target-fps``, ``--render-scale``,
  ``--lod-error``; 1 and 0: every pixel, every object as modelled);
* ``triangles``: the triangles a rank drew (of a scene cut into parts, only the parts its
  pieces needed); ``planned_triangles``: those of the whole objects the plan gave it (the
  balancer's load); ``culling_cpu_ms``: the cull of those parts (inside ``rendering_cpu_ms``);
* ``frame_ms``: the frame period, from this rank's last frame shown to this one (the run's frame
  rate; the phases add up to less: the timing rows' gather, records and mosaics lie between);
  ``latency_ms``: from the frame's input phase to its presentation (input to photon; with
  ``--latency N`` about N + 1 periods); ``*_waited_ms``: the part of each component's wall time
  the rank's own thread did not run (``time.thread_time``): waiting for peers, the GL or a core;
* ``heartbeat_cpu_ms``: CPU time of the rank's heartbeat thread since the last frame
  (``time.thread_time`` in the thread; already inside the phases' process CPU times where it
  ran during them, shown apart so its cost is known).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from multigpu.decompositions import REGISTRY as DECOMPOSITIONS
from multigpu.errors import WriteFailed
from multigpu.strategies import REGISTRY as STRATEGIES

COLUMNS = ["frame", "rank", "triangles", "x0", "y0", "x1", "y1",
           "load_balancing_ms", "rendering_ms", "synchronization_ms", "frame_exchange_ms", "display_ms", "frame_ms",
           "load_balancing_cpu_ms", "rendering_cpu_ms", "frame_exchange_cpu_ms", "display_cpu_ms",
           "bytes_sent", "objects", "pieces", "depth_bytes", "load_cv",
           "present_ms", "swap_wait_ms", "swap_ms", "swap_skew_ms", "input_ms", "heartbeat_cpu_ms",
           "learning_cpu_ms", "projection_cpu_ms", "planning_cpu_ms", "planned_triangles", "culling_cpu_ms",
           "latency_ms", "load_balancing_waited_ms", "rendering_waited_ms", "synchronization_waited_ms",
           "frame_exchange_waited_ms", "display_waited_ms", "render_scale", "lod_error_px", "choosing_cpu_ms",
           "wire_bytes", "compress_cpu_ms", "decompress_cpu_ms", "lossy_bits", "posing_cpu_ms", "animating_cpu_ms",
           "step", "step_ready", "step_late", "step_wanted", "step_delay_ms", "step_transfer_ms", "step_kept_ms",
           "balance", "restarts"]
#: the load balancing CPU time's phases (learn, pose, project, choose, plan), adding up to it
BALANCE_CPU = ("learning_cpu_ms", "posing_cpu_ms", "projection_cpu_ms", "choosing_cpu_ms", "planning_cpu_ms")
COMPONENTS = ["load_balancing_ms", "rendering_ms", "synchronization_ms", "frame_exchange_ms", "display_ms"]
#: the part of each component's wall time the rank's thread did not run (waited), by component
WAITED = {c: c.replace("_ms", "_waited_ms") for c in COMPONENTS}
#: what the ``balance`` column can name: a strategy of the screen decomposition, or another decomposition
BALANCE_NAMES = (*STRATEGIES, *(d for d in DECOMPOSITIONS if d != "screen"))
#: a frame holds a frame-rate target when its period lies within this share of the target's
TARGET_BAND = 0.10
INT_COLUMNS = {"frame", "rank", "triangles", "x0", "y0", "x1", "y1", "bytes_sent", "objects", "pieces", "depth_bytes",
               "planned_triangles", "restarts", "wire_bytes", "lossy_bits",
               "step", "step_ready", "step_late", "step_wanted"}


class TimingWriter:
    """Appends one frame's rows to timings.csv at a time, whole or not at all.

    Each frame's K rows are one ``write`` on an unbuffered file; if it fails part way (disk
    full, file size limit) the file is truncated back to the last whole frame and the error
    raised, so ``read_timings`` always parses what is there and a crash loses nothing done.
    ``resume``: a restarted run goes on at the end of the file (``recovery.resume_point``
    trimmed it to whole frames).
    """

    def __init__(self, path: Path, resume: bool = False):
        self.path = Path(path)
        self.fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | (0 if resume else os.O_TRUNC), 0o644)
        self.size = os.fstat(self.fd).st_size if resume else 0
        if self.size == 0:
            self._append((",".join(COLUMNS) + "\n").encode())

    def write(self, rows: np.ndarray) -> None:
        text = "".join(",".join(_cell(c, v) for c, v in zip(COLUMNS, row)) + "\n" for row in rows)  # K rows
        self._append(text.encode())

    def _append(self, data: bytes) -> None:
        try:
            done = 0
            while done < len(data):
                done += os.pwrite(self.fd, data[done:], self.size + done)
        except OSError as exc:
            try:
                os.ftruncate(self.fd, self.size)
            except OSError:
                pass
            raise WriteFailed.of(self.path, exc, f"kept {self.size} bytes of whole rows") from None
        self.size += len(data)

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def _cell(column: str, v: float) -> str:
    if column == "balance":
        return BALANCE_NAMES[int(v)]
    return str(int(v)) if column in INT_COLUMNS else f"{v:.4f}"


def read_timings(path: Path) -> np.ndarray:
    """timings.csv back to an (R, len(COLUMNS)) float array (``balance`` as its index in
    ``BALANCE_NAMES``)."""
    with open(path) as f:
        next(f, None)  # the header
        return parse_rows(f)


def parse_rows(lines) -> np.ndarray:
    """Lines of timings.csv rows (no header) to an (R, len(COLUMNS)) float array."""
    data = np.loadtxt(lines, delimiter=",", ndmin=2,
                      converters={COLUMNS.index("balance"): lambda s: float(BALANCE_NAMES.index(s))})
    return data.reshape(-1, len(COLUMNS))


def table(summary: dict, title: str = "") -> str:
    """The summary as the paper's Table 1 row (plus the emulated parallel figures)."""
    if not summary.get("frames"):
        return "no complete frames"
    w = summary["wall"]
    head = f"{'Frame(ms)':>10} {'FPS':>7} {'LoadBal':>8} {'Render':>8} {'Sync':>8} {'Exchange':>9} {'Display':>8}"
    row = (f"{summary['frame_ms']:10.2f} {summary['fps']:7.2f} {w['load_balancing_ms']:8.2f} "
           f"{w['rendering_ms']:8.2f} {w['synchronization_ms']:8.2f} {w['frame_exchange_ms']:9.2f} "
           f"{w['display_ms']:8.2f}")
    c = summary["cpu"]
    lines = [title] if title else []
    lines += [f"{summary['frames']} frames x {summary['ranks']} ranks. Wall-clock per-rank means (ms):", head, row,
              f"Per-rank CPU time (ms): load balancing {c['load_balancing_cpu_ms']:.2f}{_parts(c)}, rendering "
              f"{c['rendering_cpu_ms']:.2f} (slowest rank {summary['render_cpu_max_ms']:.2f}{_cull(c)}), exchange "
              f"{c['frame_exchange_cpu_ms']:.2f}, display {c['display_cpu_ms']:.2f}; heartbeat thread "
              f"{c.get('heartbeat_cpu_ms', 0.0):.3f}",
              _waits(summary),
              f"Emulated parallel frame (slowest rank's CPU time): {summary['emulated_frame_ms']:.2f} ms = "
              f"{summary['emulated_fps']:.2f} FPS (median {summary['emulated_frame_ms_median']:.2f} ms); balancing and "
              f"culling {100 * summary.get('balancing_share', 0.0):.1f} % of it",
              f"Imbalance max/mean: triangles {_fmt(summary['imbalance_triangles'])}, render CPU time "
              f"{_fmt(summary['imbalance_render_cpu'])}{_empty(summary)}; bytes exchanged per frame "
              f"{summary['bytes_sent_per_frame']:.0f}{_wire(summary)}"]
    if "target" in summary:
        t, q = summary["target"], summary.get("quality", {})
        lines.append(f"Target {t['target_fps']:.1f} FPS: {100 * t['within_band']:.0f} % of {t['frames_judged']} frames "
                     f"within {100 * TARGET_BAND:.0f} % of it, {100 * t['at_least_rate']:.0f} % at "
                     f"{100 - 100 * TARGET_BAND:.0f} % of it or faster ({t['fps']:.1f} FPS); "
                     f"{t['reduced_frames']} frames below full quality (render scale "
                     f"{q.get('render_scale_mean', 1.0):.2f}, LOD bound {q.get('lod_error_px_mean', 0.0):.2f} px "
                     "on average)")
    if "series" in summary:  # a simulation's time series (``rank/series.py``)
        sr = summary["series"]
        lines.append(f"Series: {sr['steps_shown']} steps shown, {sr['step_changes']} step changes, "
                     f"{sr['late_frames']} frames showing a step late (the wall held the one before)")
    return "\n".join(lines)


def _wire(summary: dict) -> str:
    """What crossed the wire between PCs, where anything did."""
    w = summary.get("wire", {})
    if not w.get("bytes_per_frame"):
        return ""
    lossy = f", {w['lossy_frames']} frames lossy" if w.get("lossy_frames") else ""
    return (f", in messages {w['bytes_per_frame']:.0f} (compress {w['compress_cpu_ms']:.2f} ms, decompress "
            f"{w['decompress_cpu_ms']:.2f} ms CPU per rank{lossy})")


def _waits(summary: dict) -> str:
    """Where the wall time went: each component's wait (its thread not running: peers, the GL's
    pixels, a core), and how long input took to reach the screen."""
    w, waited = summary["wall"], summary.get("wall_waited", {})
    names = {"load_balancing_ms": "load balancing", "rendering_ms": "rendering", "synchronization_ms": "sync",
             "frame_exchange_ms": "exchange", "display_ms": "display"}
    parts = ", ".join(f"{names[c]} {waited.get(c, 0.0):.2f} of {w[c]:.2f}" for c in COMPONENTS)
    return (f"Waited per frame (ms, the rank's thread not running): {parts}; outside the phases "
            f"{summary.get('outside_phases_ms', 0.0):.2f} (timing rows, records, mosaics); input to photon "
            f"{summary.get('input_to_photon_ms', 0.0):.2f} ms = "
            f"{summary.get('input_to_photon_frames', 0.0):.2f} frames")


def _parts(cpu: dict) -> str:
    """The load balancing CPU time's phases, where the summary has them."""
    if not all(c in cpu for c in BALANCE_CPU):
        return ""
    learn, pose, project, choose, plan = (cpu[c] for c in BALANCE_CPU)
    posing = f", pose {pose:.2f}" if pose else ""  # a moving scene's
    return f" (learn {learn:.2f}{posing}, project {project:.2f}, choose {choose:.2f}, plan {plan:.2f})"


def _cull(cpu: dict) -> str:
    """The culling of parts and a moving scene's animation inside the rendering CPU time, where a
    run had any."""
    return (f"; culling {cpu['culling_cpu_ms']:.2f}" if cpu.get("culling_cpu_ms") else "") + (
        f"; animating {cpu['animating_cpu_ms']:.2f}" if cpu.get("animating_cpu_ms") else "")


def _fmt(v) -> str:
    return "n/a" if v is None else f"{v:.3f}"


def _empty(summary: dict) -> str:
    n = summary.get("empty_frames", 0)
    return f" (over frames that drew something; {n} drew nothing)" if n else ""


def write_json(path: Path, doc: dict) -> None:
    """Write JSON atomically (temp file, then rename)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(json.dumps(doc, indent=1))
        tmp.replace(path)
    except OSError as exc:
        raise WriteFailed.of(path, exc, "the previous version kept") from None
    finally:
        tmp.unlink(missing_ok=True)
