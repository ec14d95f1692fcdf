"""A scene whose load moves across the wall: a swarm of small objects that gather and scatter.

``generate_swarm`` places one icosahedron per 20 triangles (1k to 100k objects and more, with
``--triangles``) at rest through a cube of side ``SIDE``. ``Swarm`` (its ``core.motion.Motion``)
flies them: each object heads, with a lag of its own, for its place in a tight flock about a
gathering point that travels round the cube, and back home again (``GATHER_S`` seconds a
cycle), spinning all the while. Scattered, the load lies evenly over the screen; gathered, most
of it lies in one small, moving part of it: a split made once is soon badly wrong. At rest
(time 0) every object is home, where the scene's bounds were measured; every place it visits
lies inside the cube. Pure numpy.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.motion import apply, bodies_of, rotations
from multigpu.scene.layout import Scene, assemble

#: the cube the swarm lives in (world units)
SIDE = 100.0
#: seconds of one gather-and-scatter cycle, and of the gathering point's round
GATHER_S, ROUND_S = 8.0, 12.0
#: the flock's radius, as a fraction of the side
FLOCK = 0.12


def icosahedron():
    """Unit icosahedron: 12 vertices, 20 faces, flat-ish vertex normals."""
    g = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g], [0, -1, -g], [0, 1, -g],
                  [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]], dtype=np.float64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    f = np.array([0, 11, 5, 0, 5, 1, 0, 1, 7, 0, 7, 10, 0, 10, 11, 1, 5, 9, 5, 11, 4, 11, 10, 2, 10, 7, 6, 7, 1, 8,
                  3, 9, 4, 3, 4, 2, 3, 2, 6, 3, 6, 8, 3, 8, 9, 4, 9, 5, 2, 4, 11, 6, 2, 10, 8, 6, 7, 9, 8, 1])
    return v, v.copy(), f


def generate_swarm(triangles: int, seed: int = 0) -> Scene:
    """About ``triangles`` triangles of icosahedra at rest through a cube of side ``SIDE``, z up."""
    if triangles < 1000:
        raise ValueError(f"swarm scene triangles must be >= 1000, got {triangles}")
    rng = np.random.default_rng(seed)
    n = max(1, int(triangles) // 20)
    home = rng.uniform(-0.45 * SIDE, 0.45 * SIDE, (n, 3))
    size = np.clip(1.6 * (5000.0 / n) ** (1 / 3), 0.15, 3.0) * rng.uniform(0.6, 1.2, n)
    pos, nrm, idx = icosahedron()
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    turn = rotations(axis, rng.uniform(0, 2 * np.pi, n))
    placed = np.einsum("nij,vj->nvi", turn, pos) * size[:, None, None] + home[:, None, :]
    normals = np.einsum("nij,vj->nvi", turn, nrm)
    hue = rng.uniform(0, 1, n)
    colors = np.c_[0.55 + 0.4 * np.cos(2 * np.pi * hue), 0.55 + 0.4 * np.cos(2 * np.pi * (hue - 1 / 3)),
                   0.55 + 0.4 * np.cos(2 * np.pi * (hue - 2 / 3))]
    meta = {"generator": "swarm", "triangles": int(triangles), "seed": int(seed), "up": [0, 0, 1], "motion": "swarm"}
    return assemble([(placed, normals, idx, colors)], f"swarm-{triangles}-s{seed}", meta)


class Swarm:
    """The swarm's flight (a ``core.motion.Motion``): every object a body of its own."""

    def __init__(self, scene: Scene):
        self.bodies = bodies_of(scene)
        n = int(self.bodies.max()) + 1 if self.bodies.size else 0
        rest = np.zeros((n, 3))
        rest[self.bodies] = (np.asarray(scene.bmin) + np.asarray(scene.bmax)) / 2 - np.asarray(scene.origin)
        self.home = rest  # each body's centre at rest, local
        self.middle = np.asarray(scene.origin, dtype=np.float64) * 0  # the cube's centre, local (the origin)
        rng = np.random.default_rng(int(scene.meta.get("seed", 0)) + 1)
        place = rng.normal(size=(n, 3))
        self.place = place / np.linalg.norm(place, axis=1, keepdims=True) * (
            FLOCK * SIDE * rng.uniform(0, 1, (n, 1)) ** (1 / 3))  # each one's place in the flock
        self.lag = rng.uniform(0.0, 0.15, n)  # of a cycle
        axis = rng.normal(size=(n, 3))
        self.axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
        self.spin = rng.uniform(-2.0, 2.0, n)  # radians a second
        self.moving = None  # every body moves

    def gather_point(self, t: float) -> np.ndarray:
        """(3,) where the flock gathers at time ``t``: round the cube, inside it."""
        a = 2 * np.pi * t / ROUND_S
        r = (0.5 - FLOCK) * SIDE * 0.85
        return self.middle + np.array([r * np.cos(a), r * np.sin(a), 0.35 * r * np.sin(2 * a)])

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        phase = 2 * np.pi * (t / GATHER_S - self.lag)
        s = np.where(t / GATHER_S > self.lag, 0.5 - 0.5 * np.cos(phase), 0.0)[:, None]  # 0 home, 1 gathered
        where = self.home + s * (self.gather_point(t) + self.place - self.home)
        A = rotations(self.axis, self.spin * t)
        return A, where - apply(A, self.home)
