"""A procedural CAD power plant: the built-in stand-in for the UNC Power Plant.

Thousands to millions of separate objects of the kinds a plant has (pipes, elbows, tanks,
boxes, girders, stairs, railings, valves, big machinery), with a heavy-tailed triangle count
per object and strong spatial clustering: dense machinery halls, sparse yards and a tall boiler
tower with its chimney. One size parameter (``triangles``) scales it from ~10^4 to ~10^7;
``copies`` lays N plants side by side like the paper's 6/10/15/20 plants. Deterministic for a
seed. Objects are instanced from a handful of template meshes per kind and resolution, so
generation is vectorized per (kind, resolution) group, never per object.
"""

from __future__ import annotations

import numpy as np

from multigpu.scene.layout import Scene, assemble

FOOTPRINT = np.array([200.0, 120.0])  # one plant, metres (x, y); z is up
GAP = 30.0


# ---------------------------------------------------------------- templates (unit size)

def cylinder(seg: int, caps: bool = True):
    """Unit cylinder along z in [0, 1], radius 1: positions, normals, indices."""
    a = np.linspace(0, 2 * np.pi, seg, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a), np.zeros(seg)], 1)
    side = np.concatenate([ring, ring + [0, 0, 1]])
    nside = np.concatenate([ring, ring])
    i = np.arange(seg)
    j = (i + 1) % seg
    idx = [np.stack([i, j, seg + j, i, seg + j, seg + i], 1).ravel()]
    pos, nrm = [side], [nside]
    if caps:
        for z, sgn in ((0.0, -1.0), (1.0, 1.0)):
            base = sum(p.shape[0] for p in pos)
            pos.append(np.concatenate([[[0, 0, z]], ring + [0, 0, z]]))
            nrm.append(np.tile([0, 0, sgn], (seg + 1, 1)))
            tri = np.stack([np.zeros(seg, int), 1 + i, 1 + j], 1)
            if sgn < 0:
                tri = tri[:, [0, 2, 1]]
            idx.append((base + tri).ravel())
    return np.concatenate(pos), np.concatenate(nrm), np.concatenate(idx)


def box():
    """Unit cube [-0.5, 0.5]^3 with flat normals (24 vertices, 12 triangles)."""
    pos, nrm, idx = [], [], []
    for axis in range(3):
        for s in (-0.5, 0.5):
            u, v = [(a) for a in range(3) if a != axis]
            quad = np.zeros((4, 3))
            quad[:, axis] = s
            quad[:, u] = [-0.5, 0.5, 0.5, -0.5]
            quad[:, v] = [-0.5, -0.5, 0.5, 0.5]
            n = np.zeros(3)
            n[axis] = np.sign(s)
            base = len(pos) * 4
            tri = np.array([0, 1, 2, 0, 2, 3]) if (s > 0) == (axis != 1) else np.array([0, 2, 1, 0, 3, 2])
            pos.append(quad)
            nrm.append(np.tile(n, (4, 1)))
            idx.append(base + tri)
    return np.concatenate(pos), np.concatenate(nrm), np.concatenate(idx)


def uv_sphere(seg: int, rings: int):
    """Unit sphere."""
    th = np.linspace(0, np.pi, rings + 1)
    ph = np.linspace(0, 2 * np.pi, seg + 1)
    t, p = np.meshgrid(th, ph, indexing="ij")
    pos = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    r, s = np.meshgrid(np.arange(rings), np.arange(seg), indexing="ij")
    a = r * (seg + 1) + s
    b = a + seg + 1
    idx = np.stack([a, b, a + 1, a + 1, b, b + 1], -1).reshape(-1)
    return pos, pos.copy(), idx


def torus_section(seg: int, tube: int, sweep: float = np.pi / 2, ratio: float = 0.35):
    """Quarter torus (a pipe elbow): major radius 1, tube radius ``ratio``."""
    u = np.linspace(0, sweep, seg + 1)
    v = np.linspace(0, 2 * np.pi, tube + 1)
    U, Vv = np.meshgrid(u, v, indexing="ij")
    cx, cy = np.cos(U), np.sin(U)
    nrm = np.stack([np.cos(Vv) * cx, np.cos(Vv) * cy, np.sin(Vv)], -1)
    pos = np.stack([cx, cy, np.zeros_like(cx)], -1) + ratio * nrm
    r, s = np.meshgrid(np.arange(seg), np.arange(tube), indexing="ij")
    a = r * (tube + 1) + s
    b = a + tube + 1
    idx = np.stack([a, b, a + 1, a + 1, b, b + 1], -1).reshape(-1)
    return pos.reshape(-1, 3), nrm.reshape(-1, 3), idx


def boxes_merged(centers, sizes):
    """Several boxes as one template (stairs, railings)."""
    bp, bn, bi = box()
    pos = (bp[None] * np.asarray(sizes)[:, None, :] + np.asarray(centers)[:, None, :]).reshape(-1, 3)
    nrm = np.tile(bn, (len(centers), 1))
    idx = (bi[None] + 24 * np.arange(len(centers))[:, None]).ravel()
    return pos, nrm, idx


def stairs_template(steps: int = 10):
    k = np.arange(steps)
    centers = np.stack([np.zeros(steps), (k + 0.5) / steps, (k + 0.5) / steps], 1)
    return boxes_merged(centers, np.tile([1.0, 1.0 / steps, 0.04], (steps, 1)))


def railing_template(posts: int = 6):
    k = np.arange(posts)
    centers = [[x, 0, 0.5] for x in k / (posts - 1) - 0.5] + [[0, 0, 1.0], [0, 0, 0.55]]
    sizes = [[0.02, 0.02, 1.0]] * posts + [[1.0, 0.03, 0.03], [1.0, 0.02, 0.02]]
    return boxes_merged(np.array(centers), np.array(sizes))


# ---------------------------------------------------------------- instancing

_AXES = np.array([  # rotations taking the template's z axis to z, x, y
    [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
    [[0, 0, 1], [0, 1, 0], [-1, 0, 0]],
    [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
], dtype=np.float64)


def instance(template, scale, rot, offset, color):
    """Place ``n`` copies: positions = (template * scale) @ rot.T + offset; normals follow."""
    tp, tn, ti = template
    pos = np.einsum("nij,nvj->nvi", rot, tp[None] * scale[:, None, :]) + offset[:, None, :]
    nrm = np.einsum("nij,nvj->nvi", rot, tn[None] / np.maximum(scale[:, None, :], 1e-9))
    nrm /= np.maximum(np.linalg.norm(nrm, axis=2, keepdims=True), 1e-12)
    return pos, nrm, ti, color


def z_rotation(angle):
    c, s = np.cos(angle), np.sin(angle)
    r = np.zeros((len(angle), 3, 3))
    r[:, 0, 0], r[:, 0, 1], r[:, 1, 0], r[:, 1, 1], r[:, 2, 2] = c, -s, s, c, 1
    return r


# ---------------------------------------------------------------- the plant

def halls(rng) -> np.ndarray:
    """Machinery hall rectangles [x0, y0, x1, y1] within one footprint (dense zones)."""
    return np.array([[15, 15, 75, 55], [110, 60, 170, 105], [20, 75, 60, 110]], dtype=np.float64)


TOWER = np.array([150.0, 25.0])  # boiler tower position in the footprint


def _zone_points(rng, n, dense_share, z_max, plant_origin):
    """Ground points: ``dense_share`` of them in the halls, the rest spread over the yard."""
    h = halls(rng)
    k = rng.random(n) < dense_share
    which = rng.integers(0, len(h), n)
    u = rng.random((n, 2))
    dense = h[which, :2] + u * (h[which, 2:] - h[which, :2])
    sparse = rng.random((n, 2)) * FOOTPRINT
    xy = np.where(k[:, None], dense, sparse)
    z = rng.random(n) * z_max
    return np.c_[xy, z] + plant_origin


def _palette(rng, n, base):
    return np.clip(np.asarray(base) + rng.normal(0, 0.06, (n, 3)), 0.05, 1.0)


def _counts(budget: float, shares: dict[str, float], tris_each: dict[str, float]) -> dict[str, int]:
    return {k: int(max(0, round(budget * shares[k] / tris_each[k]))) for k in shares}


def generate_plant(triangles: int, copies: int = 1, seed: int = 0) -> Scene:
    """Generate ``copies`` plants with about ``triangles`` triangles in all."""
    if triangles < 1000:
        raise ValueError(f"plant triangles must be >= 1000, got {triangles}")
    if copies < 1:
        raise ValueError(f"plant copies must be >= 1, got {copies}")
    per_plant = triangles / copies
    cols = int(np.ceil(np.sqrt(copies)))
    parts = []
    for c in range(copies):  # a handful of plants, not objects
        origin = np.array([(c % cols) * (FOOTPRINT[0] + GAP), (c // cols) * (FOOTPRINT[1] + GAP), 0.0])
        parts += _one_plant(np.random.default_rng([seed, c]), per_plant, origin)
    meta = {"generator": "plant", "triangles": int(triangles), "copies": int(copies), "seed": int(seed),
            "up": [0, 0, 1]}
    return assemble(parts, f"plant-{triangles}-x{copies}-s{seed}", meta)


def _one_plant(rng, budget: float, origin: np.ndarray) -> list:
    """One plant's parts; the generator's draws happen in a fixed order (deterministic)."""
    parts = _landmarks(rng, budget, origin)
    n = _piping(rng, budget, origin, parts)
    _structure(rng, n, origin, parts)
    return parts


def _landmarks(rng, budget: float, origin: np.ndarray) -> list:
    """The few huge machines (the heavy tail) and the boiler tower with its chimney."""
    parts = []
    # heavy tail: a few huge machines (turbine casings, generators), up to 1e5 triangles each
    big_tris = int(np.clip(budget * 0.04, 200, 100_000))
    seg = max(8, int(np.sqrt(big_tris / 2)))
    n_big = max(1, int(budget * 0.2 / big_tris))
    sph = uv_sphere(seg, seg // 2 + 1)
    p = _zone_points(rng, n_big, 1.0, 0.0, origin)
    scale = np.c_[rng.uniform(4, 8, n_big), rng.uniform(3, 5, n_big), rng.uniform(3, 5, n_big)]
    p[:, 2] = scale[:, 2]
    parts.append(instance(sph, scale, z_rotation(rng.uniform(0, np.pi, n_big)), p,
                          _palette(rng, n_big, [0.25, 0.45, 0.75])))

    # tower: boiler column (high-res cylinder) and a chimney
    tower_seg = int(np.clip(budget * 0.01 / 4, 16, 4096))
    cyl = cylinder(tower_seg)
    t0 = np.r_[TOWER, 0.0] + origin
    parts.append(instance(cyl, np.array([[6.0, 6.0, 60.0], [2.5, 2.5, 95.0]]), np.stack([_AXES[0]] * 2),
                          np.stack([t0, t0 + [14, 0, 0]]), np.array([[0.75, 0.72, 0.68], [0.6, 0.3, 0.25]])))
    return parts


def _piping(rng, budget: float, origin: np.ndarray, parts: list) -> dict:
    """Pipes at heavy-tailed tessellation levels, elbows, valves and tanks; returns the part
    counts of every kind (the structure uses the rest)."""
    # heavy-tailed tessellation levels for pipes and tanks
    levels = np.array([6, 8, 12, 16, 24, 32, 48, 64, 128])
    probs = 1.0 / levels**1.6
    probs /= probs.sum()
    tris_cyl = {s: cylinder(s, caps=False)[2].size // 3 for s in levels}
    mean_pipe = float(sum(probs[i] * tris_cyl[s] for i, s in enumerate(levels)))
    shares = {"pipe": 0.26, "elbow": 0.08, "valve": 0.05, "tank": 0.1, "box": 0.05, "girder": 0.06,
              "stairs": 0.03, "railing": 0.03, "tower_girder": 0.04}
    each = {"pipe": mean_pipe, "elbow": 192, "valve": 120, "tank": 3 * 48, "box": 12, "girder": 12,
            "stairs": 120, "railing": 96, "tower_girder": 12}
    n = _counts(budget, shares, each)

    # pipes: along x, y or z, radius 0.1-0.6, length 2-25; mostly in the halls
    seg_of = rng.choice(levels, size=n["pipe"], p=probs)
    for s in np.unique(seg_of):  # one group per tessellation level
        m = int((seg_of == s).sum())
        axis = rng.choice(3, size=m, p=[0.4, 0.4, 0.2])
        r = rng.uniform(0.1, 0.6, m) * (1 + s / 64)
        length = np.where(axis == 0, rng.uniform(2, 8, m), rng.uniform(2, 25, m))  # risers are short
        pos = _zone_points(rng, m, 0.85, 14.0, origin)
        parts.append(instance(cylinder(int(s), caps=False), np.c_[r, r, length], _AXES[axis], pos,
                              _palette(rng, m, [0.7, 0.55, 0.2])))

    # elbows (quarter tori) joining pipes
    m = n["elbow"]
    pos = _zone_points(rng, m, 0.9, 14.0, origin)
    r = rng.uniform(0.4, 1.2, m)
    rot = np.einsum("nij,njk->nik", _AXES[rng.integers(0, 3, m)], z_rotation(rng.integers(0, 4, m) * np.pi / 2))
    parts.append(instance(torus_section(12, 8), np.c_[r, r, r], rot, pos, _palette(rng, m, [0.7, 0.55, 0.2])))

    # valves: small spheres on pipes
    m = n["valve"]
    pos = _zone_points(rng, m, 0.95, 12.0, origin)
    r = rng.uniform(0.2, 0.5, m)
    parts.append(instance(uv_sphere(10, 6), np.c_[r, r, r], np.tile(_AXES[0], (m, 1, 1)), pos,
                          _palette(rng, m, [0.8, 0.15, 0.1])))

    # tanks: capped cylinders standing on the ground, some in the yards
    m = n["tank"]
    pos = _zone_points(rng, m, 0.6, 0.0, origin)
    r = rng.uniform(1, 4, m)
    parts.append(instance(cylinder(48), np.c_[r, r, rng.uniform(3, 12, m)], np.tile(_AXES[0], (m, 1, 1)), pos,
                          _palette(rng, m, [0.8, 0.8, 0.78])))
    return n


def _structure(rng, n: dict, origin: np.ndarray, parts: list) -> None:
    """Machinery housings, hall girders, the tower frame, stairs, railings and the ground slab."""
    # boxes: machinery housings in the halls, sheds and containers in the yards
    m = n["box"]
    pos = _zone_points(rng, m, 0.5, 0.0, origin)
    size = np.c_[rng.uniform(0.5, 8, m), rng.uniform(0.5, 8, m), rng.uniform(0.5, 5, m)]
    pos[:, 2] = size[:, 2] / 2
    parts.append(instance(box(), size, z_rotation(rng.uniform(0, np.pi, m)), pos,
                          _palette(rng, m, [0.45, 0.5, 0.45])))

    # girders: the hall frames (long thin beams)
    m = n["girder"]
    pos = _zone_points(rng, m, 0.9, 16.0, origin)
    axis = rng.integers(0, 3, m)
    length = rng.uniform(3, 15, m)
    size = np.where((axis == 0)[:, None], np.c_[0.3 * np.ones(m), 0.3 * np.ones(m), length],
                    np.c_[length, 0.3 * np.ones(m), 0.3 * np.ones(m)])
    parts.append(instance(box(), size, np.where((axis == 2)[:, None, None], z_rotation(np.full(m, np.pi / 2)),
                                                np.tile(_AXES[0], (m, 1, 1))), pos,
                          _palette(rng, m, [0.55, 0.25, 0.2])))

    # tower frame: a dense stack of girders around the boiler (the tall structure)
    m = n["tower_girder"]
    ang = rng.uniform(0, 2 * np.pi, m)
    pos = np.c_[TOWER[0] + 8 * np.cos(ang), TOWER[1] + 8 * np.sin(ang), rng.uniform(0, 60, m)] + origin
    vertical = rng.random(m) < 0.3
    size = np.where(vertical[:, None], np.c_[0.25 * np.ones(m), 0.25 * np.ones(m), 4 * np.ones(m)],
                    np.c_[4 * np.ones(m), 0.25 * np.ones(m), 0.25 * np.ones(m)])
    parts.append(instance(box(), size, z_rotation(ang + np.pi / 2), pos, _palette(rng, m, [0.5, 0.5, 0.55])))

    # stairs and railings along the hall walkways
    for kind, tmpl, colour in (("stairs", stairs_template(), [0.6, 0.6, 0.2]),
                               ("railing", railing_template(), [0.9, 0.8, 0.1])):
        m = n[kind]
        pos = _zone_points(rng, m, 0.85, 10.0, origin)
        sc = np.c_[rng.uniform(1, 2, m), rng.uniform(2, 5, m), rng.uniform(1, 3, m)]
        parts.append(instance(tmpl, sc, z_rotation(rng.integers(0, 4, m) * np.pi / 2), pos,
                              _palette(rng, m, colour)))

    # the ground slab of the plant
    slab = np.r_[FOOTPRINT / 2, -0.25] + origin
    parts.append(instance(box(), np.array([[*FOOTPRINT, 0.5]]), _AXES[:1], slab[None], np.array([[0.35, 0.37, 0.35]])))
