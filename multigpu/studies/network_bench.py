"""``multigpu bench network``: pixels between PCs, on simulated PCs joined by a shaped network.

Three parts.

**Codecs.** Frames of the default walk rendered in this process (the plant, and the textured pump),
full-HD and 4K: a screen tile's colour, and a sort-last piece (a quarter of the objects, colour and
depth) packed as the wire packs it (``rank/composite.py``: colour, then depth in byte planes). Each
codec of ``core/wire.py`` (and zstd at level 3) compresses them: the size against raw, and the CPU
speed of compressing and decompressing (GB/s of raw pixels, one thread), beside a plain memory copy
of the same pixels (``copy``: what the shared segment within a PC costs, which a codec there would
have to beat). This is what chose the default (zstd level 1 between PCs, nothing within one).

**The pixel path.** Each stage a tile's pixels go through (readback, packing, the codec, unpacking,
composing, the mosaic's stitch), on the pipeline's own functions, in CPU ms per megapixel beside a
plain memory copy of the same bytes.

**Walls.** K simulated PCs (``simhosts.py``: each its own network and IPC namespaces, a veth link
to a bridge shaped by ``tc`` to 1 Gbit/s, or 10), one rank each on a 1xK wall; the plant and the
pump; screen and db; ``--compress none`` and ``auto``. Per run, from the links' own byte counters
(every byte the PCs sent, setup included) and the run's summary:
- MB per frame on the wire, all links together, and on the busiest PC's link;
- the codec's CPU ms per frame per rank (compress and decompress) and its share of the rank's CPU
  frame;
- the frame: the emulated frame (slowest rank's CPU time), the wall-clock frame, and of it the
  exchange and synchronization;
- the frame-rate cap the link puts on that wall: gigabit's 117 MB/s of payload (10 Gbit/s: 1170)
  over the busiest link's bytes per frame (in or out);
- whether the compressed wall's mosaics equal the raw one's, pixel for pixel.
It prints figures and asserts nothing; ``--quick``: 4 PCs at full HD, the plant, few frames.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from multigpu.studies.tables import Columns

#: payload bytes per second a link carries (Ethernet with TCP/IP headers: about 94 % of the line rate)
PAYLOAD = {"1gbit": 117e6, "10gbit": 1170e6}
SCENES = {"plant": ["--triangles", "1000000"], "pump": ["--model", "models/pump.glb"]}
TILES = {"full-HD": (1920, 1080), "4K": (3840, 2160)}
CODECS = ("lz4", "zstd", "zstd:3")
#: frames of the default walk a wall runs: (full, quick), by tile
FRAMES = {"full-HD": {False: 16, True: 6}, "4K": {False: 8, True: 4}}


#: where the results go (codecs.csv, walls.csv): docs/results/network/ holds the published ones
OUT = Path("out/network")


def bench_network(quick: bool) -> list[dict]:
    from multigpu.studies.tables import write_csv

    codec_rows = bench_codecs(quick)
    OUT.mkdir(parents=True, exist_ok=True)
    write_csv(OUT / "codecs.csv", codec_rows)
    path_rows = bench_pixel_path(quick)
    write_csv(OUT / "path.csv", path_rows)
    wall_rows = bench_walls(quick)
    write_csv(OUT / "walls.csv", wall_rows)
    print(f"results in {OUT}/ (codecs.csv, path.csv, walls.csv)")
    return codec_rows + path_rows + wall_rows


# -- codecs, in this process
def _frames(scene_args: list[str], size: tuple[int, int], picks: tuple[int, ...]):
    """(colour of the whole view, sort-last piece packed as on the wire) of frames ``picks`` of
    the default walk (sampled at 40 frames) of the scene, at ``size``."""
    from multigpu.core.camera import frame_matrices
    from multigpu.gpu.render import RegionRenderer, create_context
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import walkthrough

    spec = (SceneSpec(model=scene_args[1]) if scene_args[0] == "--model"
            else SceneSpec(triangles=int(scene_args[1])))
    scene, _ = load_scene(spec)
    path = walkthrough(scene, frames=40)
    ctx = create_context()[0]
    renderer = RegionRenderer(ctx, scene, size, "scissor")
    quarter = np.zeros(scene.n_objects, bool)
    quarter[: scene.n_objects // 4] = True
    out = []
    for f in picks:
        view, proj, light = frame_matrices(path.camera(f), size)
        colour = renderer.render(view, proj, light, (0, 0, *size), None)
        rgb, z = renderer.render(view, proj, light, (0, 0, *size), quarter, depth=True)
        n = size[0] * size[1]
        piece = np.empty(7 * n, np.uint8)
        piece[:3 * n] = rgb.reshape(-1)
        piece[3 * n:].reshape(4, n)[:] = z.view(np.uint8).reshape(n, 4).T
        out.append((np.ascontiguousarray(colour).reshape(-1), piece))
    renderer.release()
    return out


def bench_codecs(quick: bool) -> list[dict]:
    from multigpu.core import wire

    picks = (12, 28) if quick else (4, 12, 20, 28, 36)
    sizes = {"full-HD": TILES["full-HD"]} if quick else TILES
    table = Columns(("scene", "scene", "<6"), ("size", "size", "<8"), ("kind", "pixels", "<17"),
                    ("codec", "codec", "<7"), ("ratio", "raw/sent", "9.1f"), ("ratio_min", "worst", "7.1f"),
                    ("compress_gbs", "comp GB/s", "10.2f"), ("decompress_gbs", "decomp GB/s", "12.2f"))
    print(f"bench network, codecs: frames {', '.join(map(str, picks))} of the default walk (at 40 frames), "
          "one thread; raw/sent = mean over frames (worst: the least), speeds in GB/s of raw pixels (CPU time)")
    print(table.header())
    rows = []
    for scene, args in SCENES.items():
        for size_name, size in sizes.items():
            frames = _frames(args, size, picks)
            for kind, which in (("screen tile (rgb)", 0), ("sort-last rgb+z", 1)):
                rows.append(_copy_row(scene, size_name, kind, [pair[which] for pair in frames]))
                print(table.row(rows[-1]), flush=True)
                for name in CODECS:
                    codec = wire.parse(name)
                    ratios, ct, dt, raw_total = [], 0.0, 0.0, 0
                    for pair in frames:
                        raw = pair[which]
                        t0 = time.process_time()
                        msg = wire.encode(raw.copy(), codec)
                        t1 = time.process_time()
                        back, _ = wire.decode(msg, raw.nbytes)
                        t2 = time.process_time()
                        assert (back == raw).all()
                        ratios.append(raw.nbytes / msg.nbytes)
                        ct, dt, raw_total = ct + (t1 - t0), dt + (t2 - t1), raw_total + raw.nbytes
                    row = {"part": "codec", "scene": scene, "size": size_name, "kind": kind, "codec": name,
                           "ratio": float(np.mean(ratios)), "ratio_min": float(np.min(ratios)),
                           "compress_gbs": raw_total / max(ct, 1e-9) / 1e9,
                           "decompress_gbs": raw_total / max(dt, 1e-9) / 1e9}
                    rows.append(row)
                    print(table.row(row), flush=True)
    return rows


def _copy_row(scene: str, size: str, kind: str, raws: list[np.ndarray]) -> dict:
    """What a plain memory copy of the same pixels runs at (the shared segment's cost within a PC:
    what a codec there would have to beat)."""
    dst = [np.empty_like(r) for r in raws]
    t0 = time.process_time()
    for _ in range(5):
        for a, b in zip(dst, raws):
            np.copyto(a, b)
    took = (time.process_time() - t0) / 5
    speed = sum(r.nbytes for r in raws) / max(took, 1e-9) / 1e9
    return {"part": "codec", "scene": scene, "size": size, "kind": kind, "codec": "copy", "ratio": 1.0,
            "ratio_min": 1.0, "compress_gbs": speed, "decompress_gbs": speed}


# -- the pixel path, stage by stage, in this process
def bench_pixel_path(quick: bool) -> list[dict]:
    """Each stage a tile's pixels go through, timed on the pipeline's own functions over the plant's
    frames, in CPU ms per megapixel (one thread), beside a memory copy of the same bytes (this
    machine's limit): the readback (the GL's pixels into the rank's array, the draw already done),
    packing a message (``composite._pack``: raw; ``_pack_planar``: for a codec), the codec
    (``wire.encode``/``decode``), unpacking the planes (``_unpack_planar``), composing
    (``merge.merge_part``: a colour copy, or a sort-last depth merge) and the mosaic's stitch."""
    from multigpu.gpu.render import create_context
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.scene.paths import walkthrough

    sizes = {"full-HD": TILES["full-HD"]} if quick else TILES
    scene, _ = load_scene(SceneSpec(triangles=int(SCENES["plant"][1])))
    path = walkthrough(scene, frames=40)
    ctx = create_context()[0]
    table = Columns(("size", "tile", "<8"), ("stage", "stage", "<34"), ("ms_per_mp", "ms/MP", "8.2f"),
                    ("gbs", "GB/s", "7.2f"), ("of_copy", "x copy", "7.1f"))
    print("\nbench network, the pixel path: CPU ms per megapixel of a tile (one thread, the plant, frames 12 and 28 "
          "of the default walk at 40), GB/s of the bytes each stage writes, and its time over a plain copy of them")
    print(table.header())
    rows = []
    for size_name, size in sizes.items():
        for row in _path_rows(ctx, scene, path, size_name, size):
            rows.append(row)
            print(table.row(row), flush=True)
    ctx.release()
    return rows


def _path_rows(ctx, scene, path, size_name: str, size: tuple[int, int]) -> list[dict]:
    """The pixel path's rows for one tile size (``bench_pixel_path``)."""
    from multigpu.core import wire
    from multigpu.core.camera import frame_matrices
    from multigpu.core.merge import merge_part
    from multigpu.core.work import Piece
    from multigpu.gpu.render import RegionRenderer
    from multigpu.rank.composite import _pack, _pack_planar, _unpack_planar
    from multigpu.records.mosaic import stitch

    w, h = size
    rows, mp, n = [], w * h / 1e6, w * h
    renderer = RegionRenderer(ctx, scene, (w, h), "scissor")
    spent: dict[str, list[float]] = {}

    def timed(stage: str, nbytes: int, fn):
        t0 = time.process_time()
        out = fn()
        spent.setdefault(stage, []).append(time.process_time() - t0)
        sizes_of[stage] = nbytes
        return out

    sizes_of: dict[str, int] = {}
    for f in (12, 28):
        view, proj, light = frame_matrices(path.camera(f), (w, h))
        rect = (0, 0, w, h)
        for depth in (False, True):
            tag = " (rgb+z)" if depth else " (rgb)"
            pending = renderer.submit(view, proj, light, [(rect, None, None)], depth=depth, ahead=True)
            (rgb, z), = pending.read()  # the draw done (llvmpipe draws at the read): now the read alone

            def read_again():
                renderer.fbo.read_into(rgb, viewport=rect, components=3, alignment=1)
                if depth:
                    renderer.fbo.read_into(z, viewport=rect, components=1, attachment=-1, dtype="f4", alignment=1)

            timed("readback" + tag, n * (7 if depth else 3), read_again)
            parts, rendered = [Piece(0, 1, 0, rect)], [(rgb, z)]
            buf = np.empty(n * (7 if depth else 3), np.uint8)  # as the pipeline's: new each frame
            timed("pack a message, raw" + tag, buf.nbytes, lambda: _pack(buf, parts, [rect], rendered, depth))
            timed("pack a message, planes" + tag, buf.nbytes,
                  lambda: _pack_planar(buf, parts, [rect], rendered, depth))
            msg = timed("zstd:1 encode" + tag, buf.nbytes, lambda: wire.encode(buf, wire.AUTO))
            got, _ = timed("zstd:1 decode" + tag, buf.nbytes, lambda: wire.decode(msg, buf.nbytes))
            views = timed("unpack the planes" + tag, n * 4 if depth else 0,
                          lambda: _unpack_planar(got, parts, depth))
            tile = np.zeros((h, w, 3), np.uint8)  # a rank's tile: its pages long touched
            tz = np.ones((h, w), np.float32) if depth else None
            timed("compose (merge_part)" + tag, n * (7 if depth else 3),
                  lambda: merge_part(tile, tz, (0, 0), rect, views[0][1], views[0][2]))
            dst = np.zeros_like(buf)  # its pages touched: the copy alone
            timed("memory copy" + tag, buf.nbytes, lambda: np.copyto(dst, buf))
        tiles = np.stack([tile] * 4)
        timed("mosaic stitch (4 tiles, per tile)", n * 3,
              lambda: stitch(tiles, [(i * w, 0, (i + 1) * w, h) for i in range(4)], (4 * w, h)))
    renderer.release()
    for stage, times in spent.items():
        took = float(np.median(times))
        if stage.startswith("mosaic"):
            took /= 4
        copy = float(np.median(spent["memory copy" + (" (rgb+z)" if "rgb+z" in stage else " (rgb)")]))
        row = {"part": "path", "size": size_name, "stage": stage, "ms_per_mp": took * 1e3 / mp,
               "gbs": sizes_of[stage] / max(took, 1e-9) / 1e9 if sizes_of[stage] else 0.0,
               "of_copy": took / max(copy, 1e-9)}
        rows.append(row)
    return rows


# -- walls, on simulated PCs
def _mosaics(out: Path) -> list[np.ndarray]:
    from PIL import Image

    return [np.asarray(Image.open(p)) for p in sorted((out / "mosaic").glob("frame_*.png"))]


def bench_walls(quick: bool) -> list[dict]:
    from multigpu.studies.runs import walk
    from multigpu.studies.simhosts import SimHosts

    if quick:
        cases = [(4, "full-HD", "plant", d, "1gbit") for d in ("screen", "db")]
    else:
        cases = [(pcs, tile, scene, d, "1gbit") for tile, pcs_list in (("full-HD", (2, 4)), ("4K", (4,)))
                 for pcs in pcs_list for scene in SCENES for d in ("screen", "db")]
        cases += [(4, "full-HD", "plant", d, "10gbit") for d in ("screen", "db")]
    table = Columns(("pcs", "PCs", "3d"), ("tile", "tile", "<8"), ("scene", "scene", "<6"),
                    ("decomposition", "decomp", "<7"), ("link", "link", "<7"), ("compress", "compress", "<9"),
                    ("mb_frame", "MB/frame", "9.2f"), ("mb_exchange", "exchange", "9.2f"),
                    ("mb_busiest", "busiest", "8.2f"),
                    ("codec_ms", "codec ms", "9.2f"), ("codec_share", "of CPU", "7.1%"),
                    ("emulated_ms", "emulated", "9.1f"), ("frame_ms", "frame", "8.1f"),
                    ("exchange_ms", "exch ms", "8.1f"), ("sync_ms", "sync", "7.1f"), ("cap_fps", "cap fps", "8.1f"),
                    ("exact", "exact", ">6"))
    print("\nbench network, walls: 1xK walls of one rank per simulated PC, the default walk at "
          f"{FRAMES['full-HD'][quick]} frames (4K: {FRAMES['4K'][quick]}), as a user runs it (mosaics at its first "
          "and last frame); MB per frame on the links (everything the PCs sent: setup, mosaics, heartbeats), of it "
          "the frame exchange's messages, and on the busiest PC's link (in or out); codec = compress + decompress "
          "CPU ms per rank per frame and its share of the rank's CPU frame; emulated = slowest rank's CPU frame; "
          "frame, exch ms, sync: wall-clock ms per rank; cap = the link's payload rate over the busiest link's bytes "
          "per frame; exact: the mosaics equal the raw run's (lossy: the frames moved, not expected)")
    print(table.header(), flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for pcs, tile_name, scene, decomposition, link in cases:
            names = [f"pc{i}" for i in range(pcs)]
            raw_mosaics = None
            frames = FRAMES[tile_name][quick]
            variants = {"none": ["--compress", "none"], "auto": ["--compress", "auto"]}
            if tile_name == "4K":  # frames in motion: 3 colour bits dropped on the wire
                variants["lossy 3"] = ["--compress", "auto", "--compress-moving", "3"]
            with SimHosts(names, Path(tmp) / "hosts", network=True, rate=link) as hosts:
                for compress, flags in variants.items():
                    out = Path(tmp) / f"{pcs}-{tile_name}-{scene}-{decomposition}-{link}-{compress.replace(' ', '')}"
                    before = hosts.wire()
                    run = walk(out, (1, pcs), TILES[tile_name],
                               [*SCENES[scene], "--frames", str(frames), "--decomposition", decomposition, *flags,
                                "--no-overlay"], 3600,
                               env={**hosts.env, "MULTIGPU_CACHE": os.environ.get("MULTIGPU_CACHE",
                                                                                  str(Path(tmp) / "c"))},
                               hosts=[(n, 1) for n in names])
                    after = hosts.wire()
                    sent = {h: after[h][0] - before[h][0] for h in after}
                    got = {h: after[h][1] - before[h][1] for h in after}
                    mosaics = _mosaics(out)
                    if compress == "none":
                        raw_mosaics, exact = mosaics, "-"
                    elif compress.startswith("lossy"):
                        exact = "-"
                    else:
                        exact = "yes" if len(mosaics) == len(raw_mosaics) and all(
                            (a == b).all() for a, b in zip(mosaics, raw_mosaics)) else "NO"
                    rows.append(_row(run, pcs, tile_name, scene, decomposition, link, compress, sent, got, frames,
                                     exact))
                    print(table.row(rows[-1]), flush=True)
    return rows


def _row(run, pcs, tile, scene, decomposition, link, compress, sent, got, frames, exact) -> dict:
    s = run.summary
    n = s["frames"]
    total = sum(sent.values()) / n
    busiest = max(max(sent.values()), max(got.values())) / n
    codec = s["wire"]["compress_cpu_ms"] + s["wire"]["decompress_cpu_ms"]
    cpu = run.col("load_balancing_cpu_ms") + run.col("rendering_cpu_ms") + run.col("frame_exchange_cpu_ms") + \
        run.col("display_cpu_ms")
    return {"part": "wall", "pcs": pcs, "tile": tile, "scene": scene, "decomposition": decomposition, "link": link,
            "compress": compress, "frames": n, "mb_frame": total / 1e6,
            "mb_exchange": s["wire"]["bytes_per_frame"] / 1e6,
            "mb_busiest": busiest / 1e6,
            "codec_ms": codec, "codec_share": codec / max(float(cpu.mean()), 1e-9),
            "emulated_ms": s["emulated_frame_ms"], "frame_ms": s["frame_ms"],
            "exchange_ms": s["wall"]["frame_exchange_ms"], "sync_ms": s["wall"]["synchronization_ms"],
            "cap_fps": PAYLOAD[link] / max(busiest, 1.0), "exact": exact,
            "compress_chosen": s["config"].get("compress", "")}
