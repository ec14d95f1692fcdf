"""A city: many small objects on a few large ground pieces (the case where per-frame overhead
dominates balancing). Deterministic for a seed; generated vectorized per kind, never per object.

Blocks of a square street grid hold buildings (boxes of 12 triangles, some with a 4-sided
pyramid roof), with a heavy-tailed skyline: a downtown of towers whose height falls with the
distance from the centre. Streets carry cars (boxes), sidewalks carry trees (low cylinders
and cones) and lamp posts; the ground is a handful of big slabs (one per quarter) and street
strips, so a few objects cover most pixels while thousands carry the triangles. Z is up.
"""

from __future__ import annotations

import numpy as np

from multigpu.scene.layout import Scene, assemble
from multigpu.scene.plant import _AXES, box, cylinder, instance, z_rotation

BLOCK = 40.0  # street grid pitch, metres
STREET = 10.0


def _cone(seg: int = 8):
    """A closed cone (apex at z = 1, base radius 1 at z = 0): ``seg`` sides + base."""
    a = np.linspace(0, 2 * np.pi, seg, endpoint=False)
    ring = np.c_[np.cos(a), np.sin(a), np.zeros(seg)]
    pos = np.vstack([ring, [[0, 0, 1.0]], [[0, 0, 0.0]]])
    nrm = np.vstack([np.c_[ring[:, :2], np.full(seg, 0.5)], [[0, 0, 1.0]], [[0, 0, -1.0]]])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    i = np.arange(seg)
    j = (i + 1) % seg
    side = np.c_[i, j, np.full(seg, seg)]
    base = np.c_[j, i, np.full(seg, seg + 1)]
    return pos, nrm, np.vstack([side, base]).ravel().astype(np.int64)


def generate_city(triangles: int, seed: int = 0) -> Scene:
    """About ``triangles`` triangles of city on a square grid sized to hold them."""
    if triangles < 1000:
        raise ValueError(f"city triangles must be >= 1000, got {triangles}")
    rng = np.random.default_rng(seed)
    # per block: ~10 buildings (12-16 tris), ~8 trees (2 x 16), ~6 cars (12), 4 lamps (12): ~550 triangles
    blocks = max(4, int(round(np.sqrt(triangles / 550.0))))
    side = blocks * BLOCK
    parts = []
    centre = np.array([side / 2, side / 2])
    # ground: four big slabs and the street strips
    q = side / 2
    slab_c = np.array([[q / 2, q / 2, -0.3], [q * 1.5, q / 2, -0.3], [q / 2, q * 1.5, -0.3],
                       [q * 1.5, q * 1.5, -0.3]])
    parts.append(instance(box(), np.tile([q, q, 0.5], (4, 1)), np.tile(_AXES[0], (4, 1, 1)), slab_c,
                          np.tile([0.3, 0.36, 0.3], (4, 1))))
    lines = (np.arange(blocks + 1) * BLOCK)
    sx = np.c_[np.full(blocks + 1, side / 2), lines, np.full(blocks + 1, 0.02)]
    sy = np.c_[lines, np.full(blocks + 1, side / 2), np.full(blocks + 1, 0.03)]
    street = np.tile([0.22, 0.22, 0.24], (blocks + 1, 1))
    flat = np.tile(_AXES[0], (blocks + 1, 1, 1))
    parts.append(instance(box(), np.tile([side, STREET, 0.05], (blocks + 1, 1)), flat, sx, street))
    parts.append(instance(box(), np.tile([STREET, side, 0.05], (blocks + 1, 1)), flat, sy, street))
    # buildings: 10 per block on a jittered 3 x 4 lot grid, height heavy-tailed towards downtown
    bx, by = np.meshgrid(np.arange(blocks), np.arange(blocks), indexing="ij")
    lot = np.stack(np.meshgrid(np.arange(3), np.arange(4), indexing="ij"), -1).reshape(-1, 2)[:10]
    base = np.repeat(np.c_[bx.ravel(), by.ravel()] * BLOCK + STREET / 2 + 3, len(lot), 0)
    pos = base + np.tile(lot * [9.0, 7.0], (blocks * blocks, 1)) + rng.uniform(0, 2, (len(base), 2))
    n = len(pos)
    dist = np.linalg.norm(pos - centre, axis=1) / max(side / 2, 1.0)
    height = np.clip(rng.pareto(2.2, n) * 12 * np.exp(-2.5 * dist) + rng.uniform(4, 10, n), 3, 160)
    size = np.c_[rng.uniform(5, 8, n), rng.uniform(4, 6, n), height]
    grey = rng.uniform(0.45, 0.8, n)
    parts.append(instance(box(), size, z_rotation(np.zeros(n)), np.c_[pos + size[:, :2] / 2, height / 2],
                          np.c_[grey, grey * rng.uniform(0.9, 1.0, n), grey * rng.uniform(0.85, 1.05, n)]))
    roofed = rng.random(n) < 0.35
    m = int(roofed.sum())
    roof = np.c_[size[roofed, :2] * 0.7, rng.uniform(2, 5, m)]
    parts.append(instance(_cone(4), roof, z_rotation(np.full(m, np.pi / 4)),
                          np.c_[pos[roofed] + size[roofed, :2] / 2, height[roofed]], np.tile([0.5, 0.25, 0.2], (m, 1))))
    # sidewalk trees (trunk + crown), lamps, and cars on the streets
    k = blocks * blocks
    t = np.repeat(np.c_[bx.ravel(), by.ravel()] * BLOCK, 8, 0) + rng.uniform(STREET / 2, BLOCK - STREET / 2,
                                                                             (8 * k, 2))
    nt = len(t)
    trunk = np.c_[np.full(nt, 0.25), np.full(nt, 0.25), np.full(nt, 2.5)]
    parts.append(instance(cylinder(8), trunk, np.tile(_AXES[0], (nt, 1, 1)), np.c_[t, np.full(nt, 1.25)],
                          np.tile([0.4, 0.3, 0.2], (nt, 1))))
    crown = rng.uniform(1.5, 2.5, nt)
    parts.append(instance(_cone(8), np.c_[crown, crown, crown * 2], z_rotation(rng.uniform(0, np.pi, nt)),
                          np.c_[t, np.full(nt, 2.5)], np.c_[rng.uniform(0.1, 0.25, nt), rng.uniform(0.4, 0.6, nt),
                                                            rng.uniform(0.1, 0.2, nt)]))
    corners = np.tile([[4, 4], [36, 4], [4, 36], [36, 36]], (k, 1))
    lamps = np.repeat(np.c_[bx.ravel(), by.ravel()] * BLOCK, 4, 0) + corners
    nl = len(lamps)
    parts.append(instance(box(), np.tile([0.2, 0.2, 6.0], (nl, 1)), np.tile(_AXES[0], (nl, 1, 1)),
                          np.c_[lamps, np.full(nl, 3.0)], np.tile([0.7, 0.7, 0.6], (nl, 1))))
    nc = 6 * k
    along = rng.random(nc) < 0.5
    lane = rng.integers(0, blocks + 1, nc) * BLOCK + rng.choice([-2.0, 2.0], nc)
    run = rng.uniform(0, side, nc)
    car = np.where(along[:, None], np.c_[run, lane], np.c_[lane, run])
    parts.append(instance(box(), np.tile([4.2, 1.8, 1.4], (nc, 1)), z_rotation(np.where(along, 0.0, np.pi / 2)),
                          np.c_[car, np.full(nc, 0.7)], rng.uniform(0.2, 0.95, (nc, 3))))
    meta = {"generator": "city", "triangles": int(triangles), "seed": int(seed), "up": [0, 0, 1],
            "route": street_route(blocks)}
    return assemble(parts, f"city-{triangles}-s{seed}", meta)


def street_route(blocks: int, eye: float = 6.0) -> list[dict]:
    """A drive along the streets at ``eye`` metres: east along the second street, north through
    downtown, west, north, east again; keyframes at the intersections, each looking at the
    next one (``paths.walkthrough`` follows it)."""
    lo, hi, mid = 1, blocks - 1, blocks // 2
    nodes = [(lo, lo), (hi, lo), (hi, mid), (lo, mid), (lo, hi), (hi, hi)]
    pts = []
    for (x0, y0), (x1, y1) in zip(nodes[:-1], nodes[1:]):  # legs of the route, not objects
        steps = max(abs(x1 - x0), abs(y1 - y0))
        for i in range(steps):
            pts.append((x0 + (x1 - x0) * i / steps, y0 + (y1 - y0) * i / steps))
    pts.append(nodes[-1])
    world = [(x * BLOCK, y * BLOCK) for x, y in pts]
    (ax, ay), (bx, by) = world[-2], world[-1]
    ahead = world[1:] + [(2 * bx - ax, 2 * by - ay)]  # the last one looks on along its street
    return [{"position": [x, y, eye], "target": [nx, ny, eye * 0.6]} for (x, y), (nx, ny) in zip(world, ahead)]
