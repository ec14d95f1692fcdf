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
