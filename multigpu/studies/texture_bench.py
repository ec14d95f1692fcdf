"""``multigpu bench textures``: what a colour texture costs: load time, frame time and memory.

One scanned-style model (``scene/scan.py``: 10^6 even triangles in one closed surface; 2x10^5
with ``--quick``) written twice as GLB: in one material colour, and with a 2048x2048 colour
texture (512x512 with ``--quick``) on planar UVs; the textured one is drawn from the texel pool
(the default: one copy per host) and from a texture array per rank (``MULTIGPU_TEXTURES=array``).
Each runs a 2x2 headless walkthrough (4 ranks, ``--split grid:8``) twice: the first builds the
scene cache (the load time a user waits once), the second maps it. Every rank's proportional set
size is sampled as it runs (``memory_bench``); the frame is the run's median emulated frame
(per-rank CPU time). The cases alternate so the machine's drift falls on each.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from multigpu.studies.tables import Columns

#: the models: name -> textured
MODELS = {"plain": False, "textured": True}
#: the cases: name -> (model, texture path)
CASES = {"material colour": ("plain", "pool"), "texture, pool": ("textured", "pool"),
         "texture, array": ("textured", "array")}


def write_models(folder: Path, triangles: int, side: int) -> dict[str, Path]:
    """The scan as two GLB files, plain and textured (``side`` pixels square), by ``MODELS`` name."""
    import numpy as np
    import trimesh
    from PIL import Image
    from trimesh.visual import TextureVisuals
    from trimesh.visual.material import PBRMaterial

    from multigpu.scene.scan import scan_mesh

    verts, faces = scan_mesh(triangles)
    out = {}
    for name, textured in MODELS.items():
        mesh = trimesh.Trimesh(verts, faces, process=False)
        if textured:
            y, x = np.indices((side, side)) / side
            rgb = np.stack([0.5 + 0.5 * np.sin(40 * x), 0.5 + 0.5 * np.sin(40 * y), 0.5 + 0.5 * np.sin(25 * (x + y))],
                           axis=2)
            image = Image.fromarray((rgb * 255).astype(np.uint8), "RGB")
            mesh.visual = TextureVisuals(uv=(verts[:, :2] - verts[:, :2].min(0)) / np.ptp(verts[:, :2], 0),
                                         material=PBRMaterial(baseColorTexture=image))
        else:
            mesh.visual = TextureVisuals(material=PBRMaterial(baseColorFactor=[200, 180, 160, 255]))
        out[name] = folder / f"scan_{name}.glb"
        out[name].write_bytes(trimesh.Scene(mesh).export(file_type="glb"))
    return out


def bench_textures(quick: bool) -> list[dict]:
    """Load time, median frame and peak memory of the untextured and the textured scan, first
    run (the cache built) and cached, on 4 ranks."""
    from multigpu.errors import InputError
    from multigpu.studies.memory_bench import measure

    if not os.path.exists("/proc/self/smaps_rollup"):
        raise InputError("bench textures needs Linux's /proc/PID/smaps_rollup")
    triangles, side = (200_000, 512) if quick else (1_000_000, 2048)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        models = write_models(Path(tmp), triangles, side)
        caches = {name: os.path.join(tmp, f"cache-{i}") for i, name in enumerate(CASES)}
        print(f"scan of {triangles:,} triangles; texture {side}x{side}; 4 ranks, 2x2 tiles of 256x256")
        table = Columns(("model", "model", "<16"), ("run", "run", ">6"), ("load_seconds", "load s", "7.2f"),
                        ("frame_ms_median", "frame ms", "9.2f"), ("rank_mib", "peak PSS/rank MiB", "18.0f"),
                        ("host_mib", "peak PSS/host MiB", "18.0f"))
        print(table.header(), flush=True)
        for run in ("first", "cached"):
            for name, (model, how) in CASES.items():  # alternated: drift falls on each
                d = measure(4, triangles, caches[name], frames=60, env={"MULTIGPU_TEXTURES": how},
                            scene=["--model", str(models[model]), "--split", "grid:8"])
                d = {**d, "model": name, "run": run, "texture_side": side if MODELS[model] else 0}
                rows.append(d)
                mib = {"rank_mib": d["peak_pss_rank_max"] / 2**20, "host_mib": d["peak_pss_host"] / 2**20}
                print(table.row({**d, **mib}), flush=True)
    return rows
