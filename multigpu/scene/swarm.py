"""A scene whose load moves across the wall: a swarm of small objects that gather and scatter.

``generate_swarm`` places one icosahedron per 20 triangles (1k to 100k objects and more, with
``--triangles``) at rest through a cube of side ``SIDE``. ``Swarm`` (its ``core.motion.Motion``)
flies them, spinning all the while: each object heads, with a lag of its own, for its place in
a tight flock (``GATHER_S`` seconds), and the flock tours four far corners of the cube (the
vertices of a tetrahedron: from any side they lie apart on the screen), a leg every ``LEG_S``
seconds, until it scatters home again (at ``SCATTER_S``, a cycle every ``CYCLE_S``).
Scattered, the load lies evenly over the screen; gathered, most of it lies in one small part of
it that moves from one side of the wall to another: a split made once is soon badly wrong. At
rest (time 0) every object is home, where the scene's bounds were measured; every place it
visits lies inside the cube. Pure numpy.
"""

from __future__ import annotations

import numpy as np

from multigpu.core import jit
from multigpu.core.motion import apply, bodies_of, rotations
from multigpu.scene.layout import Scene, assemble

#: the cube the swarm lives in (world units)
SIDE = 100.0
#: seconds to gather, a leg of the tour, when the flock scatters, and a whole cycle
GATHER_S, LEG_S, SCATTER_S, CYCLE_S = 2.0, 2.0, 12.0, 16.0
#: the flock's radius, as a fraction of the side
FLOCK = 0.12
#: the corners the flock tours (a tetrahedron's vertices), as fractions of the side
TOUR = 0.3 * np.array([[1.0, 1.0, 1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0], [1.0, -1.0, -1.0]])


def smooth(x):
    """Smoothstep of ``x`` clipped to [0, 1]: 0 to 1 with no jolt at either end."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


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

    def __init__(self, scene: Scene, compiled: bool | None = None):
        self.bodies = bodies_of(scene)
        n = int(self.bodies.max()) + 1 if self.bodies.size else 0
        rest = np.zeros((n, 3))
        rest[self.bodies] = (np.asarray(scene.bmin) + np.asarray(scene.bmax)) / 2 - np.asarray(scene.origin)
        self.home = rest  # each body's centre at rest, local (the cube's centre is the origin)
        rng = np.random.default_rng(int(scene.meta.get("seed", 0)) + 1)
        place = rng.normal(size=(n, 3))
        self.place = place / np.linalg.norm(place, axis=1, keepdims=True) * (
            FLOCK * SIDE * rng.uniform(0, 1, (n, 1)) ** (1 / 3))  # each one's place in the flock
        self.lag = rng.uniform(0.0, 0.5, n)  # seconds
        axis = rng.normal(size=(n, 3))
        self.axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
        self.spin = rng.uniform(-2.0, 2.0, n)  # radians a second
        self.moving = None  # every body moves
        self.compiled = jit.use(compiled)  # the flight in one compiled pass (``swarm_kernel.py``)
        self._A, self._b = (np.empty((n, 3, 3)), np.empty((n, 3))) if self.compiled else (None, None)

    @staticmethod
    def gather_point(t: float) -> np.ndarray:
        """(3,) where the flock is at time ``t``: at a corner of its tour for the first third of
        a leg, then on its way to the next."""
        k = int(np.floor(t / LEG_S))
        a, b = TOUR[k % len(TOUR)], TOUR[(k + 1) % len(TOUR)]
        return SIDE * (a + (b - a) * smooth((t / LEG_S - k - 1 / 3) * 1.5))

    def gathered(self, t: float) -> np.ndarray:
        """(n,) how far each object is from home towards its place in the flock: 0 home, 1 there."""
        u = t - self.lag
        cycle = np.mod(u, CYCLE_S)
        return np.where(u > 0, smooth(cycle / GATHER_S) * (1 - smooth((cycle - SCATTER_S) / GATHER_S)), 0.0)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Every object's map at ``t`` (compiled: the swarm's own arrays, valid till the next call)."""
        if self.compiled:
            from multigpu.scene.swarm_kernel import _fly

            gx, gy, gz = (float(v) for v in self.gather_point(t))
            _fly(float(t), gx, gy, gz, self.home, self.place, self.lag, self.axis, self.spin, GATHER_S, SCATTER_S,
                 CYCLE_S, self._A, self._b)
            return self._A, self._b
        s = self.gathered(t)[:, None]
        where = self.home + s * (self.gather_point(t) + self.place - self.home)
        A = rotations(self.axis, self.spin * t)
        return A, where - apply(A, self.home)
