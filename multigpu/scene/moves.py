"""What makes a scene move: a model's glTF animations (``--animation``), the swarm's flight,
moving machinery (``--moving``), or nothing.

``Machinery`` moves a share of any scene's bodies (modelled objects: ``core.motion.bodies_of``),
the small ones first (halls and floors stay put) and neighbours together (``chosen``), as a
plant's machinery moves: a third turn about their own upright axis, a third slide to and fro
along the ground, a third orbit a point beside them; each at a speed and phase of its own,
chosen from the scene's seed, so every rank picks the same ones. All three are one vectorized
map: a turn by ``angle(t)`` about the upright axis through a pivot, then a slide.
"""

from __future__ import annotations

import numpy as np

from multigpu.core import jit
from multigpu.core.motion import apply, bodies_of, rotations

#: the ways a body of the machinery moves (``Machinery.kind`` indexes this)
KINDS = ("turn", "slide", "orbit")
#: a body is machinery up to this share of the scene's diagonal across (larger ones move only
#: where a larger share of the bodies is asked to)
MACHINE = 0.03
#: machines picked together along the draw order (``chosen``)
RUN = 16


class Machinery:
    """``fraction`` of ``scene``'s bodies moving (a ``core.motion.Motion``)."""

    def __init__(self, scene, fraction: float, seed: int = 0, compiled: bool | None = None):
        self.compiled = jit.use(compiled)  # the maps in one compiled pass (``moves_kernel.py``)
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
        self.moving[chosen(scene, self.bodies, reach, int(round(float(fraction) * n)), rng)] = True
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
        self.which = np.flatnonzero(self.moving)  # only these are computed: the others' maps stay at rest
        self._A, self._b = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3))
        w = self.which
        self._own = (self.up[w], self.rate[w], self.pivot[w], self.slide[w], self.pace[w], self.phase[w])

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        up, rate, pivot, slide, pace, phase = self._own
        if self.compiled:
            from multigpu.scene.moves_kernel import _machine

            _machine(float(t), self.which, up, rate, pivot, slide, pace, phase, self._A, self._b)
            return self._A, self._b
        A = rotations(up, rate * t)
        to_and_fro = np.sin(2 * np.pi * pace * t + phase) - np.sin(phase)  # 0 at rest
        self._A[self.which] = A
        self._b[self.which] = pivot - apply(A, pivot) + to_and_fro[:, None] * slide
        return self._A, self._b


def chosen(scene, bodies: np.ndarray, reach: np.ndarray, k: int, rng) -> np.ndarray:
    """``k`` bodies to move: machinery, not the building (the bodies up to ``MACHINE`` of the
    scene's diagonal across first, the next smallest where more are asked for), in runs of ``RUN``
    neighbours along the renderer's draw order (``core.drawlist.scene_order``: a hall's machines
    together), so the moving objects' draw commands stay few."""
    from multigpu.core.drawlist import scene_order

    seq = bodies[scene_order(scene)[0]]
    _, first = np.unique(seq, return_index=True)
    along = seq[np.sort(first)]  # each body once, where the draw order first meets it
    size = np.linalg.norm(np.asarray(scene.bounds[1]) - np.asarray(scene.bounds[0]))
    small = reach[along] <= MACHINE * size
    machines, others = along[small], along[~small][np.argsort(reach[along[~small]], kind="stable")]
    if k > len(machines):
        return np.concatenate([machines, others[:k - len(machines)]])
    runs = [machines[i:i + RUN] for i in range(0, len(machines), RUN)]  # runs, not bodies
    return np.concatenate([runs[i] for i in rng.permutation(len(runs))] or [machines])[:k]


def moves(scene, spec) -> bool:
    """Whether ``scene`` moves under ``spec``: known from its meta alone. ``--anim-speed 0`` holds
    every scene at rest, posing nothing (a moving scene's still twin)."""
    played = "gltf" in scene.meta and spec.animation != "none"
    return spec.anim_speed != 0 and (scene.meta.get("motion") == "swarm" or spec.moving > 0 or played)


def movers_of(scene, spec) -> np.ndarray | None:
    """(N,) bool the objects that move where some stand still (``Posed.objects``), else None."""
    motion = motion_of(scene, spec)
    moving = getattr(motion, "moving", None)
    if moving is None:
        return None
    movers = np.asarray(moving, dtype=bool)[motion.bodies]
    return None if movers.all() else movers


def motion_of(scene, spec):
    """The scene's motion for ``spec`` (a ``models.SceneSpec``), or None where it stands still."""
    if not moves(scene, spec):
        return None
    if "gltf" in scene.meta and spec.animation != "none":  # a model's own animations (``gltf_motion.py``)
        from multigpu.scene.gltf_motion import GltfMotion

        return GltfMotion(scene, spec.animation)
    if scene.meta.get("motion") == "swarm":
        from multigpu.scene.swarm import Swarm

        return Swarm(scene)
    return Machinery(scene, spec.moving, spec.seed)
