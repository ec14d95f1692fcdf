"""What makes a scene move: its own flight (the swarm), moving machinery (``--moving``), or none.

``Machinery`` moves a share of any scene's bodies (modelled objects: ``core.motion.bodies_of``)
as a plant's machinery moves: a third turn about their own upright axis, a third slide to and
fro along the ground, a third orbit a point beside them; each at a speed and phase of its own,
chosen from the scene's seed, so every rank picks the same ones. All three are one vectorized
map: a turn by ``angle(t)`` about the upright axis through a pivot, then a slide.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.motion import apply, bodies_of, rotations

#: the ways a body of the machinery moves (``Machinery.kind`` indexes this)
KINDS = ("turn", "slide", "orbit")


class Machinery:
    """``fraction`` of ``scene``'s bodies moving (a ``core.motion.Motion``)."""

    def __init__(self, scene, fraction: float, seed: int = 0):
        self.bodies = bodies_of(scene)
        n = int(self.bodies.max()) + 1 if self.bodies.size else 0
        origin = np.asarray(scene.origin, dtype=np.float64)
        lo = np.full((n, 3), np.inf)
        hi = np.full((n, 3), -np.inf)
        np.minimum.at(lo, self.bodies, np.asarray(scene.bmin, dtype=np.float64) - origin)
        np.maximum.at(hi, self.bodies, np.asarray(scene.bmax, dtype=np.float64) - origin)
        centre, reach = (lo + hi) / 2, np.linalg.norm(hi - lo, axis=1) / 2
        rng = np.random.default_rng(int(seed) + 7)
        self.moving = np.zeros(n, dtype=bool)
        self.moving[rng.permutation(n)[:int(round(float(fraction) * n))]] = True
        up = np.asarray(scene.meta.get("up", [0, 0, 1]), dtype=np.float64)
        self.up = np.tile(up / np.linalg.norm(up), (n, 1))
        side = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
        side /= np.linalg.norm(side)
        heading = rng.uniform(0, 2 * np.pi, n)
        ground = rotations(self.up, heading) @ side  # (n, 3) a direction along the ground each
        self.kind = rng.integers(0, len(KINDS), n)
        turns, slides, orbits = ((self.kind == k) & self.moving for k in range(3))  # the others stay
        self.rate = np.where(turns | orbits, rng.uniform(0.3, 1.2, n) * rng.choice([-1, 1], n), 0.0)  # rad/s
        self.pivot = centre + np.where(orbits, 1.5 * reach, 0.0)[:, None] * ground
        self.slide = np.where(slides, np.minimum(0.5 * reach, 3.0), 0.0)[:, None] * ground  # amplitude
        self.pace = rng.uniform(0.2, 0.6, n)  # slides a second
        self.phase = rng.uniform(0, 2 * np.pi, n)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        A = rotations(self.up, self.rate * t)
        to_and_fro = np.sin(2 * np.pi * self.pace * t + self.phase) - np.sin(self.phase)  # 0 at rest
        return A, self.pivot - apply(A, self.pivot) + to_and_fro[:, None] * self.slide


def moves(scene, spec) -> bool:
    """Whether ``scene`` moves under ``spec`` (``motion_of`` is not None): known from its meta alone."""
    return scene.meta.get("motion") == "swarm" or spec.moving > 0


def motion_of(scene, spec):
    """The scene's motion for ``spec`` (a ``models.SceneSpec``), or None where it stands still."""
    if scene.meta.get("motion") == "swarm":
        from multigpu.scene.swarm import Swarm

        return Swarm(scene)
    if spec.moving > 0:
        return Machinery(scene, spec.moving, spec.seed)
    return None
