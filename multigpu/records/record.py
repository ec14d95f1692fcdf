"""Rank 0's record of a run: timings.csv, summary.json, mosaics, video, progress and ``--record``.

Rows reach the CSV a whole frame at a time and before anything else of that frame, so the
summary, rewritten every ``SUMMARY_EVERY`` frames and whenever the run ends, always describes
exactly the rows written; the recorded camera path (``--record``) grows with it, holding the
camera of every frame written. Nothing here grows with the run's length: rows are added to a
running tally (``records/tally.py``) a checkpoint's batch at a time and let go, cameras are
appended to the path file as they are written. No MPI here: the frame loop hands over the
gathered rows and images.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from multigpu.config import SUMMARY_EVERY
from multigpu.core import jit
from multigpu.decompositions import REGISTRY
from multigpu.display.colorbar import stamp
from multigpu.display.hud import overlay
from multigpu.errors import WriteFailed
from multigpu.records.mosaic import save_png
from multigpu.records.outdir import OutputDir
from multigpu.records.recovery import Recovery, restarts
from multigpu.records.report import COLUMNS, TimingWriter, table, write_json
from multigpu.records.tally import RunningSummary, summarize_file, tally_file
from multigpu.scene.models import axis_name


class Video:
    """The mosaics as an mp4 (imageio's ffmpeg writer). The encoder's own errors, on a frame or
    at the end (a full disk, an encoder that died), become one ``WriteFailed`` naming the file: the
    run then stops as for any output that cannot be written, and a truncated video never ends
    in exit 0. ffmpeg that fails to write its file still exits quietly here, so ``close`` reads
    the finished file's frames back (a stream copy, no decoding) and counts them."""

    def __init__(self, path: Path):
        import imageio.v2 as imageio

        self.path, self.frames = path, 0
        try:
            self.writer = imageio.get_writer(str(path), fps=30, macro_block_size=1)
        except Exception as exc:  # imageio's and ffmpeg's own error types
            raise self._failed(exc) from None

    def _failed(self, exc: Exception) -> WriteFailed:
        if isinstance(exc, OSError) and exc.strerror:
            return WriteFailed.of(self.path, exc)
        first = next((ln.strip() for ln in str(exc).splitlines() if ln.strip()), exc.__class__.__name__)
        return WriteFailed(f"cannot write {self.path}: {first}")

    def append(self, img: np.ndarray) -> None:
        try:
            self.writer.append_data(img)
        except Exception as exc:
            raise self._failed(exc) from None
        self.frames += 1

    def close(self) -> None:
        """Finish the file (the encoder flushes and exits here: its failure is the file's)."""
        writer, self.writer = self.writer, None
        if writer is None:
            return
        try:
            writer.close()
        except Exception as exc:
            raise self._failed(exc) from None
        if self.frames:
            from imageio_ffmpeg import count_frames_and_secs

            try:
                found = count_frames_and_secs(str(self.path))[0]
            except Exception:  # ffmpeg cannot read it: the file was cut short
                found = None
            if found != self.frames:
                whole = "it cannot be read back" if found is None else f"it holds {found} of {self.frames} frames"
                raise WriteFailed(f"cannot write {self.path}: the encoder did not finish it ({whole})")


class RunRecord:
    """What a run leaves in ``--out``; ``config`` and ``report`` go into summary.json."""

    def __init__(self, out: OutputDir, ranks: int, n_frames: int, config: dict, report, video: bool,
                 progress: bool, overlay_mosaics: bool, record: str | None = None, resume_at: int = 0):
        self.out, self.K, self.n_frames = out, ranks, n_frames
        self.config, self.report = config, report
        self.overlay = overlay_mosaics
        self.tally = RunningSummary(ranks, *tally_options(config))
        self.batch: list[np.ndarray] = []  # rows of the frames since the last checkpoint (at most SUMMARY_EVERY)
        self.record_to = Path(record) if record else None
        self.path = None
        if self.record_to is not None:
            from multigpu.scene.pathfile import PathAppender

            self.path = PathAppender(self.record_to)
        self.cameras: list = []  # (13,) position, target, up, fov, near, far, scene time of the frames not yet written
        self.failed: WriteFailed | None = None  # the first output that could not be written
        self.extra: dict = {}  # figures the frame loop adds to summary.json at the end
        self.key: np.ndarray | None = None  # a simulation's colour bar (``legend``), on the annotated mosaics
        self.done = resume_at
        self.recovery = Recovery.resumed(resume_at)  # a restarted run goes on with the same files
        if not resume_at:
            out.clear_previous()
        elif self.path is not None:
            self.path.resume(resume_at)
        self.writer = TimingWriter(out.path / "timings.csv", resume=bool(resume_at))
        if resume_at:  # the rows before the failure count in the summary as if the run had not stopped
            tally_file(out.path / "timings.csv", self.tally, ranks)
        self.video = self.bar = None
        self.summary(complete=False)
        if video:
            name = f"mosaic-r{restarts()}.mp4" if resume_at else "mosaic.mp4"  # an mp4 cannot be resumed
            self.video = Video(out.path / name)
        if progress:
            from tqdm import tqdm

            self.bar = tqdm(total=n_frames, initial=resume_at, unit="frame", desc=f"{ranks} ranks", dynamic_ncols=True,
                            mininterval=1.0)

    @property
    def recorded(self) -> int:
        """Frames in the path file on disk."""
        return self.path.frames if self.path is not None else 0

    def camera(self, cam, time: float | None = None, step: int | None = None) -> None:
        """The next frame's camera (path-file coordinates), a moving scene's time and a series'
        step shown, kept for ``--record``."""
        self.cameras.append([*cam.position, *cam.target, *cam.up, cam.fov, cam.near, cam.far,
                             float("nan") if time is None else time, float("nan") if step is None else step])

    def _save_path(self) -> None:
        """Append the cameras of the frames written since the last time to the ``--record`` file."""
        if self.path is None or self.recorded == self.done:
            return
        n = self.done - self.recorded
        try:
            self.path.append(np.array(self.cameras[:n], dtype=np.float64))
        except OSError as exc:
            kept = f"kept its first {self.recorded} frames" if self.recorded else ""
            raise WriteFailed.of(self.record_to, exc, kept) from None
        del self.cameras[:n]

    def rows(self, f: int, rows: np.ndarray) -> None:
        """Frame ``f``'s (K, len(COLUMNS)) rows: to the CSV first, then the tally."""
        self.writer.write(rows)
        self.recovery.shown(f)
        self.batch.append(rows[np.argsort(rows[:, COLUMNS.index("rank")], kind="stable")])
        self.done = f + 1
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(fps=f"{1e3 / max(rows[:, COLUMNS.index('frame_ms')].max(), 1e-9):.1f}", refresh=False)
        if f % SUMMARY_EVERY == SUMMARY_EVERY - 1:
            self.summary(complete=False)
            self._save_path()

    def legend(self, meta: dict) -> None:
        """The colour bar of a scene coloured by a field (``display.colorbar``), where it is one."""
        from multigpu.display.colorbar import color_bar, legend_of

        got = legend_of(meta)
        if got is not None:
            from multigpu.scene.simulation import lookup

            self.key = color_bar(got, lookup(got["colormap"]))

    def image(self, f: int, img: np.ndarray, rects, mosaic: bool, eyes: list | None = None,
              outputs: list | None = None) -> None:
        """The stitched wall of frame ``f``: a mosaic PNG (and its partition overlay) when
        ``mosaic``, a video frame when recording one. A stereo wall's ``eyes`` (left, right)
        go beside it, in ``mosaic/left`` and ``mosaic/right``, the partition over the left eye's; a
        projector wall's ``outputs`` (name, picture) in ``mosaic/outputs/NAME``, as sent to each."""
        if mosaic:
            folder = self.out.path / "mosaic"
            save_png(img, folder / f"frame_{f:05d}.png")
            kept = [(name, eye) for name, eye in zip(("left", "right"), eyes or ())]  # eyes
            kept += [(f"outputs/{name}", picture) for name, picture in outputs or ()]  # projectors
            for name, picture in kept:
                try:
                    (folder / name).mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise WriteFailed.of(folder / name, exc) from None
                save_png(picture, folder / name / f"frame_{f:05d}.png")
            if self.overlay:
                marked = overlay(img if eyes is None else eyes[0], rects)
                marked = marked if self.key is None else stamp(marked, self.key)  # a simulation's colour bar
                save_png(marked, folder / f"frame_{f:05d}_partition.png")
        if self.video is not None:
            self.video.append(img)

    def summary(self, complete: bool, stopped_by: str | None = None) -> dict:
        """Rewrite summary.json from the tally, the rows since the last checkpoint added first."""
        if self.batch:
            self.tally.add(np.stack(self.batch))
            self.batch.clear()
        summary = self.tally.result()
        doc = {"complete": complete, "frames_written": self.done, "config": self.config,
               "decomposition": self.report(), **summary, **self.recovery.doc(), **self.extra}
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
        for thing in (self.bar, self.writer, self.video, self.path):
            if thing is not None:
                try:
                    thing.close()
                except WriteFailed as exc:  # a file that could not be finished (the video's encoder)
                    self.failed = self.failed or exc
                except Exception:  # closing must not hide the run's own error
                    pass
        try:
            return self.summary(complete=complete, stopped_by=stopped_by)
        except WriteFailed as exc:
            self.failed = self.failed or exc
            return self.tally.result()

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


def tally_options(config: dict) -> tuple:
    """The tally's ``hosts`` and ``target`` for a run of this configuration: the swap skew per
    host of a windowed wall on several PCs, how a ``--target-fps`` run held its rate."""
    hosts = [r.get("host") for r in config.get("ranks", [])]
    by_host = hosts if len(set(hosts)) > 1 and config.get("present") == "window" else None
    target = ((config["target_fps"], config["render_scale"], config["lod_error"])
              if config.get("target_fps") else None)
    return by_host, target


def salvage(out: Path, reason: str) -> int | None:
    """Finish the record of a job whose rank 0 was killed before closing it (its host died, the
    MPI runtime tore the job down): summary.json, last rewritten at a checkpoint, is rewritten
    from every whole frame in timings.csv, with ``stopped_by = reason``. Returns the frames it
    now describes, or None where there is nothing to finish (no record here, or rank 0 closed it)."""
    import json

    path = Path(out) / "summary.json"
    try:
        doc = json.loads(path.read_text())
        if doc.get("complete") or doc.get("stopped_by"):
            return None
        summary = summarize_file(Path(out) / "timings.csv", len(doc["config"]["ranks"]), *tally_options(doc["config"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    write_json(path, {"complete": False, "frames_written": summary["frames"], "config": doc["config"],
                      "decomposition": doc.get("decomposition"), **summary, "stopped_by": reason})
    return summary["frames"]


def config_doc(cfg, scene, load_info, n_frames, placement, renderer_method) -> dict:
    """The run's configuration for summary.json; ``placement``: every rank's host, index on
    its host (``node_rank``), EGL device and the GL renderer it opened (which GPU it draws on)."""
    return {"grid": list(cfg.grid), "tile": list(cfg.tile), "size": list(cfg.size), "strips": cfg.strips,
            "decomposition": cfg.decomposition, "latency": cfg.latency, "target_fps": cfg.target_fps,
            "render_scale": cfg.render_scale, "lod_error": cfg.lod_error,
            "balance": cfg.balance if REGISTRY[cfg.decomposition].balanced else None,
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
            "dark": list(cfg.dark),
            "monitor": cfg.monitor is not None,
            "stereo": cfg.stereo, "viewer": _viewer_doc(cfg),
            "eyes": _eyes_doc(cfg),
            "lp_num_threads": os.environ.get("LP_NUM_THREADS"),
            "kernel": {"compiled": jit.available(),
                       "warm_seconds": round(load_info.get("kernel_seconds", 0.0), 3)}}


def _viewer_doc(cfg) -> dict | None:
    """Where the viewer stands and what the wall measures (None: the camera's own frustum)."""
    v = cfg.viewer
    if v is None:
        return None
    return {"screen_m": list(v.screen), "eye_separation_m": v.separation, "swap_eyes": v.swap,
            "head_m": None if cfg.head is None else list(cfg.head), "head_poses": cfg.head_poses,
            "world_per_metre": v.world_per_metre,
            "focus": cfg.focus}  # no size given: zero parallax at the scene, parallax within 3 % (core/eyes.focused)


def run_title(cfg, scene) -> str:
    """The printout's first line: the scene, the wall and how frames are divided."""
    if cfg.decomposition == "screen":
        what = f"balance={cfg.balance}"
    elif cfg.decomposition == "hybrid":
        what = f"hybrid (balance={cfg.balance}, wide objects depth-composited)"
    elif cfg.decomposition == "bins":
        what = f"bins {cfg.bin_pattern} {cfg.bin_size}px"
    else:
        what = f"db ({cfg.db_ranges} ranges)"
    W, H = cfg.canvas.size
    (rows, cols), (tw, th) = cfg.grid, cfg.tile
    return (f"multigpu walkthrough: {scene.name}, {scene.n_triangles} triangles in {scene.n_objects} objects, "
            f"{rows}x{cols} wall ({rows} row(s) x {cols} column(s) of {tw}x{th} tiles, canvas {W}x{H}), {what}"
            + ("" if cfg.stereo == "mono" else f", stereo {cfg.stereo}"))


def _eyes_doc(cfg) -> str | None:
    """Who draws which eye: every rank both (joint), half the ranks each (split), or a rank for
    each eye of each tile (own)."""
    if cfg.stereo == "mono":
        return None
    return "own" if cfg.eyes == "own" else "split" if cfg.eyes_split else "joint"
