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
    """The swarm's flight (a ``core.motion.Motion``): every object a body of its own.

    Its per-object state is one (n, 8) float32 array (place in the flock, lag, spin axis, spin
    rate): homes are read from the scene's own bounds (the host's mapped copy), and the maps are
    made a span of bodies at a time (``at_span``) so that a rank never holds every object's map:
    at 100k objects a moving swarm costs a rank a few MB beside the same swarm at rest."""

    def __init__(self, scene: Scene, compiled: bool | None = None):
        self.bodies = bodies_of(scene)
        n = int(self.bodies.max()) + 1 if self.bodies.size else 0
        self.n = n
        self.origin = np.asarray(scene.origin, dtype=np.float64)
        self.rest = (np.asarray(scene.bmin), np.asarray(scene.bmax))
        self.own = np.array_equal(self.bodies, np.arange(scene.n_objects))  # body i is object i
        if not self.own:  # bodies of several objects: their centres kept
            rest = np.zeros((n, 3))
            rest[self.bodies] = (self.rest[0] + self.rest[1]) / 2 - self.origin
            self._home = rest
        rng = np.random.default_rng(int(scene.meta.get("seed", 0)) + 1)
        place = rng.normal(size=(n, 3))
        place = place / np.linalg.norm(place, axis=1, keepdims=True) * (
            FLOCK * SIDE * rng.uniform(0, 1, (n, 1)) ** (1 / 3))  # each one's place in the flock
        self.params = np.empty((n, 8), dtype=np.float32)
        self.params[:, :3] = place
        self.params[:, 3] = rng.uniform(0.0, 0.5, n)  # lag, seconds
        self.params[:, 4:7] = rng.normal(size=(n, 3))  # spin axis (made unit where used)
        self.params[:, 7] = rng.uniform(-2.0, 2.0, n)  # spin, radians a second
        self.moving = None  # every body moves
        self.compiled = jit.use(compiled)  # the flight in one compiled pass (``swarm_kernel.py``)

    def home(self, lo: int = 0, hi: int | None = None) -> np.ndarray:
        """(hi - lo, 3) bodies lo:hi's centres at rest, local (the cube's centre is the origin)."""
        hi = self.n if hi is None else hi
        if not self.own:
            return self._home[lo:hi]
        bmin, bmax = self.rest
        return (bmin[lo:hi] + bmax[lo:hi]) / 2 - self.origin

    @staticmethod
    def gather_point(t: float) -> np.ndarray:
        """(3,) where the flock is at time ``t``: at a corner of its tour for the first third of
        a leg, then on its way to the next."""
        k = int(np.floor(t / LEG_S))
        a, b = TOUR[k % len(TOUR)], TOUR[(k + 1) % len(TOUR)]
        return SIDE * (a + (b - a) * smooth((t / LEG_S - k - 1 / 3) * 1.5))

    @staticmethod
    def gathered(t: float, lag: np.ndarray) -> np.ndarray:
        """(n,) how far each object of ``lag`` (seconds) is from home towards its place in the
        flock: 0 home, 1 there."""
        u = t - lag
        cycle = np.mod(u, CYCLE_S)
        return np.where(u > 0, smooth(cycle / GATHER_S) * (1 - smooth((cycle - SCATTER_S) / GATHER_S)), 0.0)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Every body's map at ``t`` (new arrays)."""
        return self.at_span(t, 0, self.n)

    def at_span(self, t: float, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
        """Bodies lo:hi's maps at ``t`` (new arrays of hi - lo)."""
        if self.compiled:  # homes made in the kernel from the rest boxes: no temporaries a span
            from multigpu.scene.swarm_kernel import _fly

            A, b = np.empty((hi - lo, 3, 3)), np.empty((hi - lo, 3))
            gx, gy, gz = (float(v) for v in self.gather_point(t))
            bmin, bmax, origin = (*self.rest, self.origin) if self.own else (self._home, self._home, np.zeros(3))
            _fly(float(t), gx, gy, gz, lo, bmin, bmax, origin, self.params, GATHER_S, SCATTER_S, CYCLE_S, A, b)
            return A, b
        home, p = self.home(lo, hi), self.params[lo:hi].astype(np.float64)
        x, y, z = p[:, 4], p[:, 5], p[:, 6]
        norm = np.sqrt(x * x + y * y + z * z)
        axis = np.c_[x / norm, y / norm, z / norm]
        s = self.gathered(t, p[:, 3])[:, None]
        where = home + s * (self.gather_point(t) + p[:, :3] - home)
        A = rotations(axis, p[:, 7] * t)
        return A, where - apply(A, home)
