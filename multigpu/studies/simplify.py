"""``multigpu bench simplify``: the level-of-detail simplifier chosen by measurement.

meshoptimizer (``meshopt_simplify``, quadric collapses onto the mesh's own vertices) against
fast-simplification (Fast-Quadric-Mesh-Simplification, new optimal vertex positions), on the
same meshes at the same triangle targets (a quarter and a sixteenth): seconds per million input
triangles, the triangles reached, and the geometric error, measured the same way for both: the
symmetric Hausdorff distance and the mean distance between the two surfaces, estimated from
points sampled on each (area-weighted) to the nearest triangle of the other, as a share of the
mesh's bounding-box diagonal. Meshes: the scanned-style model (``scene scan``) and,
with ``--model FILE``, the user's. Writes ``simplify.csv`` (docs/results/simplify/).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from multigpu.errors import InputError
from multigpu.studies.tables import Columns, write_csv

#: the triangle targets, as shares of the input
TARGETS = (0.25, 1 / 16)
#: points sampled on each surface for the distance estimate
SAMPLES = 100_000


def _meshopt(v: np.ndarray, f: np.ndarray, share: float) -> tuple[np.ndarray, np.ndarray]:
    from multigpu.scene.lod import simplify

    idx, _ = simplify(np.ascontiguousarray(v, dtype=np.float32), f.ravel().astype(np.uint32),
                      int(len(f) * share), lock=False)
    return v, idx.reshape(-1, 3).astype(np.int64)


def _fast(v: np.ndarray, f: np.ndarray, share: float) -> tuple[np.ndarray, np.ndarray]:
    try:
        import fast_simplification
    except ImportError:
        raise InputError("bench simplify: fast-simplification is not installed (pip install -e '.[bench]')") from None

    pts, faces = fast_simplification.simplify(v.astype(np.float64), f.astype(np.int64), target_reduction=1 - share)
    return pts, faces


LIBRARIES = {"meshoptimizer": _meshopt, "fast-simplification": _fast}


def _sample(v: np.ndarray, f: np.ndarray, n: int, rng) -> np.ndarray:
    """``n`` points on the surface, area-weighted."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    pick = rng.choice(len(f), n, p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(n))[:, None], rng.random(n)[:, None]
    return (1 - r1) * a[pick] + r1 * (1 - r2) * b[pick] + r1 * r2 * c[pick]


def _to_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distances from points ``p`` (n, 3) to triangles ``(a, b, c)`` (n, 3) each, pairwise
    (the closest point by the triangle's Voronoi regions: Ericson, Real-Time Collision Detection 5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(invalid="ignore", divide="ignore"):
        denom = va + vb + vc
        v, w = vb / denom, vc / denom
        q = a + ab * v[:, None] + ac * w[:, None]  # inside the face
        t_ab = np.clip(d1 / (d1 - d3), 0, 1)
        t_ac = np.clip(d2 / (d2 - d6), 0, 1)
        t_bc = np.clip((d4 - d3) / ((d4 - d3) + (d5 - d6)), 0, 1)
    edges = [np.where(np.isfinite(t)[:, None], s + e * np.nan_to_num(t)[:, None], s)
             for s, e, t in ((a, ab, t_ab), (a, ac, t_ac), (b, c - b, t_bc))]
    inside = (va >= 0) & (vb >= 0) & (vc >= 0) & np.isfinite(v) & np.isfinite(w)
    best = np.min([np.linalg.norm(p - e, axis=1) for e in edges], axis=0)
    return np.where(inside, np.linalg.norm(p - q, axis=1), best)


def _to_surface(p: np.ndarray, v: np.ndarray, f: np.ndarray, k: int = 16) -> np.ndarray:
    """Each point's distance to the surface ``(v, f)``: the nearest of the ``k`` triangles whose
    centroids lie nearest it."""
    from scipy.spatial import cKDTree

    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    _, near = cKDTree((a + b + c) / 3).query(p, k=min(k, len(f)))
    near = near.reshape(len(p), -1)
    return np.min([_to_triangles(p, a[near[:, j]], b[near[:, j]], c[near[:, j]]) for j in range(near.shape[1])],
                  axis=0)


def distances(v0, f0, v1, f1, seed: int = 0) -> tuple[float, float]:
    """(Hausdorff, mean) distance between two surfaces, from points sampled on each to the other."""
    rng = np.random.default_rng(seed)
    d01 = _to_surface(_sample(v0, f0, SAMPLES, rng), v1, f1)
    d10 = _to_surface(_sample(v1, f1, SAMPLES, rng), v0, f0)
    return float(max(d01.max(), d10.max())), float((d01.mean() + d10.mean()) / 2)


def _meshes(model: str | None, quick: bool) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    import tempfile

    import trimesh

    from multigpu.scene.scan import write_scan

    out = {}
    with tempfile.TemporaryDirectory(prefix="multigpu-simplify-") as tmp:
        scan = Path(tmp) / "scan.ply"
        write_scan(scan, 20_000 if quick else 400_000)
        m = trimesh.load(scan, process=False, force="mesh")
        out["scan"] = (np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64))
    if model:
        m = trimesh.load(model, process=False, force="mesh")
        out[Path(model).name] = (np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64))
    return out


def bench_simplify(model: str | None, quick: bool, out: str = "out/simplify") -> list[dict]:
    """Run, print and write the table; its rows."""
    rows = []
    for name, (v, f) in _meshes(model, quick).items():
        diag = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
        for lib, fn in LIBRARIES.items():
            for share in TARGETS:
                t = time.perf_counter()
                v1, f1 = fn(v, f, share)
                dt = time.perf_counter() - t
                h, mean = distances(v, f, v1, f1)
                rows.append({"mesh": name, "triangles": len(f), "library": lib, "target": share,
                             "reached": len(f1) / len(f), "s_per_mtri": dt / len(f) * 1e6,
                             "hausdorff": h / diag, "mean_distance": mean / diag,
                             "new_vertices": int(v1 is not v)})
    dest = Path(out)
    dest.mkdir(parents=True, exist_ok=True)
    write_csv(dest / "simplify.csv", rows)
    table = Columns(("mesh", "mesh", ">18"), ("library", "library", ">20"), ("target", "target", "7.4f"),
                    ("reached", "reached", "8.4f"), ("s_per_mtri", "s/Mtri", "7.2f"),
                    ("hausdorff", "Hausdorff", "10.2e"), ("mean_distance", "mean", "9.2e"))
    print(table.header())
    for r in rows:
        print(table.row(r))
    print("(distances as shares of the bounding-box diagonal)")
    sys.stdout.flush()
    return rows
