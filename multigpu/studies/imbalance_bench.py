"""``multigpu bench imbalance``: what the render imbalance the default leaves is made of.

One process plays the four ranks of a 2x2 wall of 256x256 tiles along each scene's walkthrough,
as part 2 of ``bench passes`` does, ``cross`` learning from the measured times; but every rank
renders its pieces twice in a row. The two renders of the same work differ only by this
machine's noise, so each rank's deviation from its frame's mean render splits into a repeatable
part (the covariance of the two renders' deviations: what a perfect model of this frame's work
would have foreseen) and noise (half the variance of their difference). Printed per scene:

* max/mean of the first renders (the imbalance the run would show) and of the two renders' mean;
* the deviation's standard deviation, and its repeatable and noise parts (the parts' variances
  add up to the whole's);
* ``persists``: the share of the repeatable variance still there in the next frame (first
  render of one frame against the second of the next, so no noise is shared): what the last
  frame's times could still teach a balancer that reacts to them;
* ``fit leaves``: the share of the repeatable variance that a least-squares fit of the
  deviations on the work's features (triangles drawn, triangles spread over the pieces, piece
  pixels, the pixels of the object rects within the pieces, objects drawn) does not explain,
  fitted on the very frames it explains: a bound on what any linear model of those features
  could foresee.

Process CPU time, the render phase alone; no MPI. It prints figures and asserts nothing.
"""

from __future__ import annotations

import numpy as np

from multigpu.studies.tables import Columns

#: the work's features, per rank and frame (``_features``)
FEATURES = ("triangles", "spread", "pixels", "cover", "objects")


def bench_imbalance(quick: bool) -> list[dict]:
    from multigpu.gpu.render import RegionRenderer, create_context
    from multigpu.scene.models import SceneSpec, load_scene
    from multigpu.studies.passes_bench import GRID, TILE

    frames, triangles = (24, 20_000) if quick else (240, 100_000)
    ctx, _ = create_context()
    print(f"bench imbalance: cross on a 2x2 wall of 256x256, walkthrough of {frames} frames, every rank's work "
          "rendered twice (process CPU time); deviations of a rank's render from its frame's mean, relative")
    table = Columns(("scene", "scene", "<6"), ("imbalance", "max/mean", "8.3f"),
                    ("imbalance_of_two", "of 2", "6.3f"), ("deviation_sd", "dev sd", "7.3f"),
                    ("repeatable_sd", "repeat", "7.3f"), ("noise_sd", "noise", "6.3f"),
                    ("persists", "persists", "8.2f"), ("fit_leaves", "fit leaves", "10.2f"))
    print(table.header())
    rows = []
    for name in ("plant", "city"):
        scene = load_scene(SceneSpec(scene=name, triangles=triangles))[0]
        renderer = RegionRenderer(ctx, scene, (GRID[1] * TILE[0], GRID[0] * TILE[1]))
        first, second, feats = _renders(scene, renderer, frames)
        renderer.release()
        row = {"scene": name, **split(first, second, feats)}
        rows.append(row)
        print(table.row(row))
    return rows


def _renders(scene, renderer, frames: int):
    """(F, K) first and second render CPU ms of every rank's work, and its (F, K, 5) features."""
    from multigpu.core.regions import pixel_spans
    from multigpu.studies.passes_bench import _frames, rank_times

    planner, path, cfg = _frames(scene, frames, "cross")
    tris = np.asarray(scene.tris, dtype=np.float64)
    first, second, feats = [], [], []
    for f in range(len(path)):  # frames, then ranks and their pieces: not objects
        view, proj, light, rects = planner.frame(path.camera(f))
        spans, on = pixel_spans(rects, cfg.canvas.size)
        work = planner.work(f, rects)
        times = [rank_times(renderer, work, view, proj, light) for _ in range(2)]  # the same work twice
        planner.observe(f, times[0])
        if f >= 8:  # past the first frames (cross starts from the paper's strips)
            first.append(times[0])
            second.append(times[1])
            feats.append(_features(work, spans, on, tris))
    return np.array(first), np.array(second), np.array(feats)


def _features(work, spans: np.ndarray, on: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(K, 5) ``FEATURES`` of every rank's pieces (an object in two pieces counts twice)."""
    s = spans.astype(np.float64)
    area = (s[:, 2] - s[:, 0] + 1) * (s[:, 3] - s[:, 1] + 1)
    out = np.zeros((work.ranks, len(FEATURES)))
    for r in range(work.ranks):  # ranks and their pieces, each vectorized over the objects
        for (x0, y0, x1, y1), m in zip(np.asarray(work.rects[r]).tolist(), work.masks[r]):
            m = m & on
            ix = np.clip(np.minimum(s[:, 2] + 1, x1) - np.maximum(s[:, 0], x0), 0, None)
            iy = np.clip(np.minimum(s[:, 3] + 1, y1) - np.maximum(s[:, 1], y0), 0, None)
            inside = np.where(m, ix * iy, 0.0)
            out[r] += (tris[m].sum(), (tris * inside / np.maximum(area, 1.0)).sum(), (x1 - x0) * (y1 - y0),
                       inside.sum(), m.sum())
    return out


def split(first: np.ndarray, second: np.ndarray, feats: np.ndarray) -> dict:
    """The repeatable / noise split of two renders' (F, K) times of the same work (see the
    module's text), and what a fit on the (F, K, P) features leaves of the repeatable part."""

    def dev(x):
        return x / x.mean(axis=-1, keepdims=True) - 1.0

    a, b = dev(first), dev(second)
    total = float(np.mean(a * a))
    noise = float(np.mean((a - b) ** 2)) / 2
    repeat = max(float(np.mean(a * b)), 0.0)
    persists = float(np.mean(a[:-1] * b[1:])) / repeat if repeat > 0 and len(a) > 1 else float("nan")
    y = ((a + b) / 2).ravel()  # the noise halved
    x = dev(np.moveaxis(feats, -1, 0) + 1e-12)  # (P, F, K): each feature relative to its frame's mean
    x = x.reshape(x.shape[0], -1).T
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    left = max(float(np.mean((y - x @ coef) ** 2)) - noise / 2, 0.0)  # the residual's noise taken out
    both = (first + second) / 2
    return {"imbalance": float(first.max(axis=1).mean() / first.mean()),
            "imbalance_of_two": float(both.max(axis=1).mean() / both.mean()),
            "deviation_sd": total ** 0.5, "repeatable_sd": repeat ** 0.5, "noise_sd": noise ** 0.5,
            "persists": persists, "fit_leaves": left / repeat if repeat > 0 else float("nan")}
