"""Levels of detail chosen compiled (``lod.LevelChooser.choose``): one pass over the objects,
where the reference makes a dozen numpy passes over (N, L) temporaries (~0.4 ms at 7k objects).
The same levels (tests/test_lod.py). Per frame."""

from __future__ import annotations

import math

from multigpu.core.jit import compile_all


def _choose(centers, radii, error, tris, seen, which, ex, ey, ez, focal, near, bound, levels, drawn):
    """Each object ``which`` lists (those with a coarser level; the others stay at level 0): its
    coarsest level whose error ``error[i, l] * focal / distance`` is within ``bound`` pixels into
    ``levels``, its triangles into ``drawn`` (level 0 where ``seen[i, 0]`` is NaN: nobody draws
    it); how many are above level 0."""
    n_levels = error.shape[1]
    coarse = 0
    for j in range(which.shape[0]):
        i = which[j]
        if math.isnan(seen[i, 0]):
            levels[i] = 0
            drawn[i] = tris[i, 0]
            continue
        dx, dy, dz = centers[i, 0] - ex, centers[i, 1] - ey, centers[i, 2] - ez
        d = max(math.sqrt(dx * dx + dy * dy + dz * dz) - radii[i], near)
        scale = focal / d
        lv = 0
        for k in range(1, n_levels):
            if error[i, k] * scale <= bound:
                lv = k
            else:
                break
        levels[i] = lv
        drawn[i] = tris[i, lv]
        if lv:
            coarse += 1
    return coarse


compile_all(globals(), ("_choose",))
