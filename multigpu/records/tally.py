"""A run's summary kept as it goes: running sums and bounded quantiles of the timing rows.

Rank 0 adds each batch of whole frames once and never looks at it again, so the summary costs
the same at frame 100 as at frame 10,000,000 and its memory is bounded (a wall runs for days;
rebuilding the summary from every row kept grew each checkpoint with the run, issue 63). The
same tally summarizes a list of rows (``summarize``) and a timings.csv read in chunks
(``summarize_file``), so a salvaged run's summary is the one the run would have written.

Medians and percentiles are exact while a stream holds at most ``EXACT`` values; beyond, they
come from a histogram of log-spaced bins ``REL`` wide, so a quantile is within ``REL / 2`` of
the exact one (relative). Means, counts and maxima are exact at any length. Pure numpy.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from multigpu.records.report import BALANCE_CPU, BALANCE_NAMES, COLUMNS, COMPONENTS, TARGET_BAND, WAITED

#: values a quantile stream keeps exactly before it folds them into its histogram
EXACT = 1 << 13
#: the histogram's bins, relative width: a quantile of a long run is within REL / 2 of the exact one
REL = 1e-3
#: the histogram's range (ms); values below LO count as 0 (the CSV keeps 4 decimals), above HI as HI
LO, HI = 1e-4, 1e7
_STEP = np.log1p(REL)
_BINS = int(np.ceil(np.log(HI / LO) / _STEP)) + 1
#: frames per batch when summarizing rows or a file (bounded memory for any run)
BATCH = 4096
_C = {c: i for i, c in enumerate(COLUMNS)}
_CPU = [_C[c] for c in ("load_balancing_cpu_ms", "rendering_cpu_ms", "frame_exchange_cpu_ms", "display_cpu_ms")]
_CPU_SHOWN = ("load_balancing_cpu_ms", "rendering_cpu_ms", "frame_exchange_cpu_ms", "display_cpu_ms",
              "heartbeat_cpu_ms", "culling_cpu_ms", "animating_cpu_ms", *BALANCE_CPU)


class Quantiles:
    """Quantiles of a stream of values in bounded memory (see the module's note)."""

    def __init__(self):
        self.n = 0
        self.exact = np.empty(EXACT)
        self.hist: np.ndarray | None = None  # counts per bin, once more than EXACT values came

    def add(self, values) -> None:
        v = np.asarray(values, dtype=np.float64).ravel()
        if self.hist is None and self.n + v.size <= EXACT:
            self.exact[self.n:self.n + v.size] = v
        else:
            if self.hist is None:
                self.hist = np.zeros(_BINS, dtype=np.int64)
                self._fold(self.exact[:self.n])
            self._fold(v)
        self.n += v.size

    def _fold(self, v: np.ndarray) -> None:
        b = np.zeros(v.size, dtype=np.int64)
        on = v >= LO
        b[on] = 1 + np.floor(np.log(np.minimum(v[on], HI) / LO) / _STEP).astype(np.int64)
        self.hist += np.bincount(np.minimum(b, _BINS - 1), minlength=_BINS)

    def quantile(self, q: float) -> float:
        """The ``q``-th percentile (numpy's linear rule while exact; a bin's middle after)."""
        if self.n == 0:
            return 0.0
        if self.hist is None:
            return float(np.percentile(self.exact[:self.n], q))
        at = int(np.floor(q / 100.0 * (self.n - 1)))
        b = int(np.searchsorted(np.cumsum(self.hist), at, side="right"))
        return 0.0 if b == 0 else float(LO * np.exp((b - 0.5) * _STEP))


class RunningSummary:
    """The summary of a run's whole frames, added a batch at a time in frame order.

    ``hosts``: each rank's host, for the swap skew per host (a windowed wall on several PCs);
    ``target``: ``(fps, render_scale, lod_px)`` of a ``--target-fps`` run, for how it held it.
    """

    def __init__(self, ranks: int, hosts: list | None = None, target: tuple | None = None):
        self.K, self.target = ranks, target
        self.frames = 0
        self.sums = np.zeros(len(COLUMNS))  # over frames and ranks
        self.rank0 = np.zeros(len(COLUMNS))  # rank 0's column over frames (per-frame values on every row)
        self.s = dict.fromkeys(("emulated", "render_max", "outside", "latency", "imb_tri", "imb_rend", "lossy"), 0.0)
        self.drawn = 0
        self.balance = np.zeros(len(BALANCE_NAMES), dtype=np.int64)
        self.q = {k: Quantiles() for k in ("emulated", "period", "present", "skew", "input")}
        self.skew_max = 0.0
        groups = list(dict.fromkeys(hosts)) if hosts else []
        self.hosts = {str(h): ([k for k, x in enumerate(hosts) if x == h], Quantiles()) for h in groups}
        self.t = {"judged": 0, "within": 0, "rate": 0, "reduced": 0, "period": 0.0}
        # a series' steps (rank 0's column: every rank shows the same step at a frame)
        self.steps: set[int] = set()
        self.step = {"late": 0, "swaps": 0, "last": None, "seen": False}
        self.delays = Quantiles()  # a stream's steps: from their write to the first frame showing them (ms)

    def add(self, per: np.ndarray) -> None:
        """``per``: (F, K, C) rows of F whole frames, each frame's ranks in rank order."""
        per = np.asarray(per, dtype=np.float64)
        if per.shape[0] == 0:
            return
        g = lambda c: per[:, :, _C[c]]
        self.frames += per.shape[0]
        self.sums += per.sum(axis=(0, 1))
        self.rank0 += per[:, 0, :].sum(axis=0)
        emulated = per[:, :, _CPU].sum(axis=2).max(axis=1)
        period = g("frame_ms").mean(axis=1)
        tri, rend = g("triangles"), g("rendering_cpu_ms")
        drawn = tri.sum(axis=1) > 0
        s = self.s
        s["emulated"] += emulated.sum()
        s["render_max"] += rend.max(axis=1).sum()
        s["outside"] += np.maximum(g("frame_ms") - per[:, :, [_C[c] for c in COMPONENTS]].sum(axis=2), 0.0).sum()
        s["latency"] += g("latency_ms").max(axis=1).sum()
        s["lossy"] += (g("lossy_bits").max(axis=1) > 0).sum()  # frames some rank sent lossy
        for key, a in (("imb_tri", tri), ("imb_rend", rend)):  # frames that drew nothing have no balance
            a = a[drawn]
            s[key] += (a.max(axis=1) / np.maximum(a.mean(axis=1), 1e-12)).sum()
        self.drawn += int(drawn.sum())
        self.balance += np.bincount(g("balance")[:, 0].astype(np.int64), minlength=len(BALANCE_NAMES))
        skew = g("swap_skew_ms")[:, 0]
        self.skew_max = max(self.skew_max, float(skew.max()))
        for key, v in (("emulated", emulated), ("period", period), ("present", g("present_ms")), ("skew", skew),
                       ("input", g("input_ms"))):
            self.q[key].add(v)
        swap = g("swap_ms")
        for mine, q in self.hosts.values():
            q.add(swap[:, mine].max(axis=1) - swap[:, mine].min(axis=1))
        if self.target is not None:
            self._target(per, period)
        self._steps(per[:, 0, _C["step"]].astype(np.int64), per[:, 0, _C["step_late"]],
                    per[:, :, _C["step_ready"]])
        delay = per[:, 0, _C["step_delay_ms"]]
        if (delay > 0).any():
            self.delays.add(delay[delay > 0])

    def _steps(self, step: np.ndarray, late: np.ndarray, ready: np.ndarray) -> None:
        """A series' steps shown, the frames that showed a step late and the step changes."""
        st = self.step
        st["seen"] = st["seen"] or bool(step.any() or late.any() or (ready < 0).any())
        self.steps.update(np.unique(step).tolist())
        st["late"] += int((late > 0).sum())
        prev = step[0] if st["last"] is None else st["last"]
        st["swaps"] += int((np.diff(np.r_[prev, step]) != 0).sum())
        st["last"] = int(step[-1])

    def _target(self, per: np.ndarray, period: np.ndarray) -> None:
        """How the frames after the controller's warm-up held ``--target-fps``."""
        from multigpu.core.quality import WARMUP

        fps, scale, lod_px = self.target
        judged = per[:, 0, _C["frame"]] >= WARMUP
        p, r0 = period[judged], per[judged, 0, :]
        t = self.t
        t["judged"] += int(p.size)
        t["within"] += int((np.abs(p / (1e3 / fps) - 1.0) <= TARGET_BAND).sum())
        t["rate"] += int((1e3 / np.maximum(p, 1e-9) >= (1 - TARGET_BAND) * fps).sum())
        t["reduced"] += int(((r0[:, _C["render_scale"]] < scale) | (r0[:, _C["lod_error_px"]] > lod_px)).sum())
        t["period"] += float(p.sum())

    def result(self) -> dict:
        """The summary of every frame added (the keys of summary.json's breakdown)."""
        F, K = self.frames, self.K
        if F == 0:
            return {"frames": 0}
        mean = lambda c: float(self.sums[_C[c]] / (F * K))  # over frames and ranks
        per_frame = lambda c: float(self.sums[_C[c]] / F)  # summed over ranks, over frames
        first = lambda c: float(self.rank0[_C[c]] / F)  # a per-frame value (on every row), over frames
        s, q = self.s, self.q
        frame_ms = per_frame("frame_ms") / K
        emulated = s["emulated"] / F
        imb = lambda key: s[key] / self.drawn if self.drawn else None
        out = {
            "frames": int(F), "ranks": int(K),
            "wall": {c: mean(c) for c in COMPONENTS},
            "frame_ms": frame_ms, "fps": 1000.0 / frame_ms, "frame_ms_median": q["period"].quantile(50),
            "cpu": {c: mean(c) for c in _CPU_SHOWN},
            "emulated_frame_ms": emulated, "emulated_fps": 1000.0 / emulated,
            "emulated_frame_ms_median": q["emulated"].quantile(50),
            # what a frame's balancing and cull cost beside the frame they plan
            "balancing_share": (mean("load_balancing_cpu_ms") + mean("culling_cpu_ms")) / max(emulated, 1e-12),
            "render_cpu_max_ms": s["render_max"] / F,
            "imbalance_triangles": imb("imb_tri"), "imbalance_render_cpu": imb("imb_rend"),
            "empty_frames": int(F - self.drawn),
            "triangles_per_frame": per_frame("triangles"),
            "planned_triangles_per_frame": per_frame("planned_triangles"),
            "bytes_sent_per_frame": per_frame("bytes_sent"), "depth_bytes_per_frame": per_frame("depth_bytes"),
            # what travelled as messages (framed and compressed between PCs) and what that cost each rank
            "wire": {"bytes_per_frame": per_frame("wire_bytes"), "compress_cpu_ms": mean("compress_cpu_ms"),
                     "decompress_cpu_ms": mean("decompress_cpu_ms"), "lossy_frames": int(s["lossy"])},
            "load_cv": first("load_cv"),  # std/mean of per-rank triangles (Kerbl's c_v)
            "present": {"present_ms_median": q["present"].quantile(50), "present_ms_p99": q["present"].quantile(99),
                        "swap_skew_ms_median": q["skew"].quantile(50), "swap_skew_ms_p99": q["skew"].quantile(99),
                        "swap_skew_ms_max": self.skew_max},
            "balance_frames": {BALANCE_NAMES[i]: int(n) for i, n in enumerate(self.balance) if n},
            "input_ms_median": q["input"].quantile(50),
            "wall_waited": {c: mean(w) for c, w in WAITED.items()},
            "outside_phases_ms": s["outside"] / (F * K),
            "input_to_photon_ms": s["latency"] / F,
            "input_to_photon_frames": s["latency"] / F / frame_ms,
            "quality": {"render_scale_mean": first("render_scale"), "lod_error_px_mean": first("lod_error_px")},
        }
        if self.step["seen"]:  # a series played
            out["series"] = {"steps_shown": len(self.steps), "step_changes": self.step["swaps"],
                             "late_frames": self.step["late"], "last_step": self.step["last"]}
            if self.delays.n:  # a stream's stamped steps: write to first frame shown
                d = self.delays.quantile(50)
                out["series"].update(delay_ms_median=d, delay_frames_median=d / max(q["period"].quantile(50), 1e-9),
                                     delays=self.delays.n)
        if self.hosts:  # per host, its own ranks' swap skew: whether each PC's monitors swap together
            out["present"]["swap_skew_ms_by_host"] = {h: q.quantile(50) for h, (_, q) in self.hosts.items()}
        if self.target is not None:
            t, n = self.t, max(self.t["judged"], 1)
            out["target"] = {"target_fps": float(self.target[0]), "frames_judged": t["judged"],
                             "within_band": t["within"] / n, "at_least_rate": t["rate"] / n,
                             "reduced_frames": t["reduced"],
                             "fps": 1e3 * t["judged"] / t["period"] if t["judged"] else 0.0}
        return out


def whole_frames(rows: np.ndarray, ranks: int) -> np.ndarray:
    """(R, C) rows in any order to (F, K, C): the frames every rank's row reached, in frame order."""
    rows = np.asarray(rows, dtype=np.float64).reshape(-1, len(COLUMNS))
    if len(rows) == 0:
        return np.zeros((0, ranks, len(COLUMNS)))
    frames, inverse, counts = np.unique(rows[:, _C["frame"]], return_inverse=True, return_counts=True)
    rows = rows[counts[inverse.ravel()] == ranks]
    rows = rows[np.lexsort((rows[:, _C["rank"]], rows[:, _C["frame"]]))]
    return rows.reshape(-1, ranks, len(COLUMNS))


def summarize(rows: np.ndarray, ranks: int, hosts: list | None = None, target: tuple | None = None) -> dict:
    """The summary of complete frames (all ranks present) among ``rows``."""
    tally = RunningSummary(ranks, hosts, target)
    per = whole_frames(rows, ranks)
    for i in range(0, per.shape[0], BATCH):
        tally.add(per[i:i + BATCH])
    return tally.result()


def summarize_file(path: Path, ranks: int, hosts: list | None = None, target: tuple | None = None) -> dict:
    """The summary of a timings.csv (``tally_file``)."""
    tally = RunningSummary(ranks, hosts, target)
    tally_file(path, tally, ranks)
    return tally.result()


def tally_file(path: Path, tally: RunningSummary, ranks: int) -> None:
    """A timings.csv's rows into ``tally``, read ``BATCH`` frames at a time (rows reach it a whole
    frame at a time, so every chunk of ``ranks * BATCH`` rows holds whole frames)."""
    from multigpu.records.report import parse_rows

    with open(path) as f:
        next(f, None)  # the header
        while lines := list(itertools.islice(f, ranks * BATCH)):
            tally.add(whole_frames(parse_rows(lines), ranks))
