"""Rank 0's record of a run: timings.csv, summary.json, mosaics, video, progress and ``--record``.

Rows reach the CSV a whole frame at a time and before anything else of that frame, so the
summary, rewritten every ``SUMMARY_EVERY`` frames and whenever the run ends, always describes
exactly the rows written; the recorded camera path (``--record``) is rewritten with it, holding
the camera of every frame written. No MPI here: the frame loop hands over the gathered rows and images.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from multigpu.config import SUMMARY_EVERY
from multigpu.core import jit
from multigpu.display.hud import overlay
from multigpu.errors import WriteFailed
from multigpu.parallel.mosaic import save_png
from multigpu.parallel.outdir import OutputDir
from multigpu.parallel.report import COLUMNS, TimingWriter, read_timings, summarize, table, target_stats, write_json
from multigpu.scene.models import axis_name


class RunRecord:
    """What a run leaves in ``--out``; ``config`` and ``report`` go into summary.json."""

    def __init__(self, out: OutputDir, ranks: int, n_frames: int, config: dict, report, video: bool,
                 progress: bool, overlay_mosaics: bool, record: str | None = None):
        self.out, self.K, self.n_frames = out, ranks, n_frames
        self.config, self.report = config, report
        self.overlay = overlay_mosaics
        self.history: list[np.ndarray] = []
        self.record_to = Path(record) if record else None
        self.cameras: list = []  # (F, 12): position, target, up, fov, near, far of each frame written
        self.recorded = 0  # frames in the path file on disk
        self.failed: WriteFailed | None = None  # the first output that could not be written
        self.done = 0
        out.clear_previous()
        self.writer = TimingWriter(out.path / "timings.csv")
        self.video = self.bar = None
        self.summary(complete=False)
        if video:
            import imageio.v2 as imageio

            self.video = imageio.get_writer(str(out.path / "mosaic.mp4"), fps=30, macro_block_size=1)
        if progress:
            from tqdm import tqdm

            self.bar = tqdm(total=n_frames, unit="frame", desc=f"{ranks} ranks", dynamic_ncols=True, mininterval=1.0)

    def camera(self, cam) -> None:
        """The next frame's camera (path-file coordinates), kept for ``--record``."""
        self.cameras.append([*cam.position, *cam.target, *cam.up, cam.fov, cam.near, cam.far])

    def _save_path(self) -> None:
        """Rewrite the ``--record`` file (atomically) with the camera of every frame written."""
        if self.record_to is None or not self.done or self.recorded == self.done:
            return
        from multigpu.scene.paths import CameraPath

        c = np.array(self.cameras[:self.done], dtype=np.float64)
        try:
            CameraPath(c[:, 0:3], c[:, 3:6], c[:, 6:9], c[:, 9], c[:, 10], c[:, 11]).save(self.record_to)
        except OSError as exc:
            kept = f"kept its first {self.recorded} frames" if self.recorded else ""
            raise WriteFailed.of(self.record_to, exc, kept) from None
        self.recorded = self.done

    def rows(self, f: int, rows: np.ndarray) -> None:
        """Frame ``f``'s (K, len(COLUMNS)) rows: to the CSV first, then the history."""
        self.writer.write(rows)
        self.history.append(rows.copy())
        self.done = f + 1
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(fps=f"{1e3 / max(rows[:, COLUMNS.index('frame_ms')].max(), 1e-9):.1f}")
        if f % SUMMARY_EVERY == SUMMARY_EVERY - 1:
            self.summary(complete=False)
            if self.done - self.recorded >= max(SUMMARY_EVERY, self.done // 10):  # linear in frames overall
                self._save_path()

    def image(self, f: int, img: np.ndarray, rects, mosaic: bool) -> None:
        """The stitched wall of frame ``f``: a mosaic PNG (and its partition overlay) when
        ``mosaic``, a video frame when recording one."""
        if mosaic:
            save_png(img, self.out.path / "mosaic" / f"frame_{f:05d}.png")
            if self.overlay:
                save_png(overlay(img, rects), self.out.path / "mosaic" / f"frame_{f:05d}_partition.png")
        if self.video is not None:
            self.video.append_data(img)

    def summary(self, complete: bool, stopped_by: str | None = None) -> dict:
        rows = np.concatenate(self.history) if self.history else np.zeros((0, len(COLUMNS)))
        summary = summarize(rows, self.K)
        hosts = [r.get("host") for r in self.config.get("ranks", [])]
        if summary.get("frames") and len(set(hosts)) > 1 and self.config.get("present") == "window":
            summary["present"]["swap_skew_ms_by_host"] = skew_by_host(rows, self.K, hosts)
        if summary.get("frames") and self.config.get("target_fps"):
            summary["target"] = target_stats(rows, self.K, self.config["target_fps"], self.config["render_scale"],
                                             self.config["lod_error"])
        doc = {"complete": complete, "frames_written": self.done, "config": self.config,
               "decomposition": self.report(), **summary}
        if stopped_by:
            doc["stopped_by"] = stopped_by
        write_json(self.out.path / "summary.json", doc)
        return summary

    def close(self, complete: bool, stopped_by: str | None) -> dict:
        """Finish every file (each one whatever another's fate); the first write that failed, if
        any, is ``failed`` afterwards (the run then ends with it: one line, exit 2)."""
        try:
            self._save_path()
        except WriteFailed as exc:  # the timings and summary are still written
            self.failed = self.failed or exc
        for thing in (self.bar, self.writer, self.video):
            if thing is not None:
                try:
                    thing.close()
                except Exception:  # closing must not hide the run's own error
                    pass
        try:
            return self.summary(complete=complete, stopped_by=stopped_by)
        except WriteFailed as exc:
            self.failed = self.failed or exc
            return summarize(np.concatenate(self.history) if self.history else np.zeros((0, len(COLUMNS))), self.K)

    def timeline(self, ranks: list, latency: int) -> None:
        """``timeline.json``: per rank, the last frames' phases as [name, start, end] in ms from
        the earliest start (one clock per host: ranks on several hosts are each on their own)."""
        t0 = min((a for r in ranks for _, spans in r for _, a, _ in spans), default=0.0)
        doc = {"latency": latency,
               "ranks": [[{"frame": f, "phases": [[n, round((a - t0) * 1e3, 4), round((b - t0) * 1e3, 4)]
                                                  for n, a, b in spans]} for f, spans in r] for r in ranks]}
        write_json(self.out.path / "timeline.json", doc)

    def print_table(self, summary: dict, title: str) -> None:
        print(table(summary, title), flush=True)
        print(f"outputs in {self.out.path}/ (timings.csv, summary.json, mosaic/)", flush=True)
        if self.record_to is not None and self.recorded:
            print(f"camera path of the {self.recorded} frames written in {self.record_to} (replay: --path)", flush=True)


def skew_by_host(rows: np.ndarray, ranks: int, hosts: list) -> dict:
    """Per host, the median over frames of its own ranks' swap skew (latest minus earliest swap
    return among them, each host on its own clock): whether each PC's monitors swap together."""
    col = {c: i for i, c in enumerate(COLUMNS)}
    frames = rows.shape[0] // ranks
    per = rows[:frames * ranks][np.lexsort((rows[:frames * ranks, col["rank"]], rows[:frames * ranks, col["frame"]]))]
    swap = per.reshape(frames, ranks, len(COLUMNS))[:, :, col["swap_ms"]]
    out = {}
    for h in dict.fromkeys(hosts):  # hosts, a few
        mine = [k for k, x in enumerate(hosts) if x == h]
        s = swap[:, mine]
        out[str(h)] = float(np.median(s.max(axis=1) - s.min(axis=1)))
    return out


def salvage(out: Path, reason: str) -> int | None:
    """Finish the record of a job whose rank 0 was killed before closing it (its host died, the
    MPI runtime tore the job down): summary.json, last rewritten at a checkpoint, is rewritten
    from every whole frame in timings.csv, with ``stopped_by = reason``. Returns the frames it
    now describes, or None where there is nothing to finish (no record here, or rank 0 closed it)."""
    import json

    path = Path(out) / "summary.json"
    try:
        doc = json.loads(path.read_text())
        rows = read_timings(Path(out) / "timings.csv")
        ranks = len(doc["config"]["ranks"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if doc.get("complete") or doc.get("stopped_by"):
        return None
    summary = summarize(rows, ranks)
    write_json(path, {"complete": False, "frames_written": summary["frames"], "config": doc["config"],
                      "decomposition": doc.get("decomposition"), **summary, "stopped_by": reason})
    return summary["frames"]


def config_doc(cfg, scene, load_info, n_frames, placement, renderer_method) -> dict:
    """The run's configuration for summary.json; ``placement``: every rank's host, index on
    its host (``node_rank``) and EGL device."""
    return {"grid": list(cfg.grid), "tile": list(cfg.tile), "size": list(cfg.size), "strips": cfg.strips,
            "decomposition": cfg.decomposition, "latency": cfg.latency, "target_fps": cfg.target_fps,
            "render_scale": cfg.render_scale, "lod_error": cfg.lod_error,
            "balance": cfg.balance if cfg.decomposition == "screen" else None,
            "bin_size": cfg.bin_size if cfg.decomposition == "bins" else None,
            "bin_pattern": cfg.bin_pattern if cfg.decomposition == "bins" else None,
            "db_ranges": cfg.db_ranges if cfg.decomposition == "db" else None, "bounds": cfg.bounds,
            "frames_planned": n_frames,
            "subfrustum": renderer_method, "offset": list(cfg.offset), "partition": cfg.partition,
            "scene": {"name": scene.name, "objects": scene.n_objects, "triangles": scene.n_triangles,
                      "load_seconds": round(load_info["seconds"], 3), "cached": load_info["cached"],
                      "warnings": scene.meta.get("warnings", []), "objects_from": scene.meta.get("objects"),
                      "up": axis_name(scene.meta.get("up", [0, 0, 1])), "up_source": scene.meta.get("up_source"),
                      "lods": scene.meta.get("lods")},
            "path": cfg.path or cfg.path_kind, "egl_device": placement[0]["egl_device"], "present": cfg.present,
            "ranks": placement, "hosts": len({p["host"] for p in placement}),
            "mullion": list(cfg.mullion), "canvas": list(cfg.canvas.size), "wall": cfg.wall, "record": cfg.record,
            "monitor": cfg.monitor is not None,
            "lp_num_threads": os.environ.get("LP_NUM_THREADS"),
            "kernel": {"compiled": jit.available(),
                       "warm_seconds": round(load_info.get("kernel_seconds", 0.0), 3)}}


def run_title(cfg, scene) -> str:
    """The printout's first line: the scene, the wall and how frames are divided."""
    if cfg.decomposition == "screen":
        what = f"balance={cfg.balance}"
    elif cfg.decomposition == "bins":
        what = f"bins {cfg.bin_pattern} {cfg.bin_size}px"
    else:
        what = f"db ({cfg.db_ranges} ranges)"
    W, H = cfg.canvas.size
    return (f"multigpu walkthrough: {scene.name}, {scene.n_triangles} triangles in {scene.n_objects} objects, "
            f"{cfg.grid[0]}x{cfg.grid[1]} wall of {W}x{H}, {what}")
