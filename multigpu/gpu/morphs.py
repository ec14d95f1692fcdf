"""A glTF model's morph targets on the GL: each vertex's row of deltas (a vertex attribute), the
deltas and each frame's weights (storage buffers), each object's weights (first, count): what
the vertex shader's ``MORPH`` path reads (``shaders.py``) before it applies the object's map."""

from __future__ import annotations

import numpy as np


class MorphBuffers:
    """The GL buffers of ``scene``'s morph targets (``Scene.morph_rows``, ``morph_deltas``)."""

    def __init__(self, ctx, scene):
        self.targets = int(scene.morph_deltas.shape[1])
        self.rows = ctx.buffer(np.ascontiguousarray(scene.morph_rows, dtype=np.int32))
        deltas = np.zeros((max(len(scene.morph_deltas), 1), self.targets, 4), dtype=np.float32)
        deltas[:len(scene.morph_deltas), :, :3] = scene.morph_deltas
        self.deltas = ctx.buffer(deltas)
        self.of = ctx.buffer(np.zeros((scene.n_objects, 2), dtype=np.int32))  # no object morphs till told
        self.weights = ctx.buffer(reserve=4)

    def attribute(self) -> tuple:
        """The vertex array's entry for the rows."""
        return (self.rows, "1i", "in_morph")

    def update(self, weights: np.ndarray | None, morph_of: np.ndarray | None = None) -> None:
        """A frame's weights (orphaned first: frames still drawn keep theirs); ``morph_of`` (N, 2):
        each object's first weight and count, once."""
        if morph_of is not None:
            self.of.write(np.ascontiguousarray(morph_of, dtype=np.int32))
        if weights is not None and len(weights):
            data = np.ascontiguousarray(weights, dtype=np.float32)
            self.weights.orphan(data.nbytes)
            self.weights.write(data)

    def bind(self, prog) -> None:
        prog["morph_targets"].value = self.targets
        self.deltas.bind_to_storage_buffer(5)
        self.weights.bind_to_storage_buffer(6)
        self.of.bind_to_storage_buffer(7)

    def release(self) -> None:
        for b in (self.rows, self.deltas, self.of, self.weights):
            b.release()


class SkinBuffers:
    """The GL buffers of ``scene``'s skins: each vertex's joints and weights (vertex attributes)
    and the frame's joint palette (a storage buffer of three rows ``[A | b]`` a joint)."""

    def __init__(self, ctx, scene):
        self.joints = ctx.buffer(np.ascontiguousarray(scene.skin_joints, dtype=np.uint16))
        self.weights = ctx.buffer(np.ascontiguousarray(scene.skin_weights, dtype=np.float32))
        self.palette = ctx.buffer(reserve=48)

    def attributes(self) -> list:
        return [(self.joints, "4u2", "in_joints"), (self.weights, "4f", "in_weights")]

    def update(self, palette) -> None:
        """A frame's joint maps ((J, 3, 3), (J, 3): ``GltfMotion.last_palette``), orphaned first."""
        if palette is None:
            return
        A, b = palette
        rows = np.ascontiguousarray(np.concatenate([A, b[:, :, None]], axis=2), dtype=np.float32)
        self.palette.orphan(rows.nbytes)
        self.palette.write(rows)

    def bind(self) -> None:
        self.palette.bind_to_storage_buffer(8)

    def release(self) -> None:
        for b in (self.joints, self.weights, self.palette):
            b.release()
