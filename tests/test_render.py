"""The renderer's GL vertices: positions as they are, normals packed to 32 bits, and the
lighting they give equal to that of the scene's float normals."""

import numpy as np
import pytest

from multigpu.gpu.buffers import pack_normals
from multigpu.scene.layout import Scene


def _decode(packed: np.ndarray) -> np.ndarray:
    """The vertex shader's decoding, in numpy (the GL test below checks the shader itself)."""
    f = np.stack([packed & 0xFFFF, packed >> 16], axis=1) / 65535.0 * 2.0 - 1.0
    n = np.concatenate([f, 1.0 - np.abs(f).sum(axis=1, keepdims=True)], axis=1)
    t = np.maximum(-n[:, 2], 0.0)
    n[:, 0] += np.where(n[:, 0] >= 0, -t, t)
    n[:, 1] += np.where(n[:, 1] >= 0, -t, t)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_packed_normals_keep_their_direction_everywhere_on_the_sphere():
    rng = np.random.default_rng(4)
    n = rng.normal(size=(100_000, 3))
    n = np.concatenate([n / np.linalg.norm(n, axis=1, keepdims=True), np.eye(3), -np.eye(3),
                        [[1e-30, -1e-30, 1.0]], [[0.6, 0.0, -0.8]]])
    scaled = n * rng.uniform(1e-6, 1e6, size=(n.shape[0], 1))  # direction, not length, is kept
    angle = np.degrees(np.arccos(np.clip((_decode(pack_normals(scaled)) * n).sum(axis=1), -1, 1)))
    assert angle.max() < 0.01
    assert np.allclose(_decode(pack_normals(np.zeros((1, 3)))), [[0, 0, 1]], atol=1e-4)  # zero: +z


def _one_triangle(normal) -> Scene:
    """A triangle covering the whole clip square, every vertex with ``normal``, white."""
    pos = np.array([[-1, -1, 0], [3, -1, 0], [-1, 3, 0]], dtype=np.float32)
    verts = np.concatenate([pos, np.tile(np.asarray(normal, np.float32), (3, 1))], axis=1)
    one = lambda *v: np.array([v], dtype=np.float64)
    return Scene(vertices=verts, indices=np.arange(3, dtype=np.uint32), first_index=np.zeros(1, np.int64),
                 index_count=np.full(1, 3, np.int64), base_vertex=np.zeros(1, np.int64), bmin=one(-1, -1, 0),
                 bmax=one(3, 3, 0), centers=one(1, 1, 0), radii=np.ones(1), colors=np.ones((1, 3), np.float32))


def test_the_shader_lights_packed_normals_as_the_float_ones():
    from multigpu.gpu.render import EglUnavailable, RegionRenderer, create_context

    try:
        ctx, _ = create_context()
    except EglUnavailable as exc:
        pytest.skip(str(exc))
    light = np.array([0.3, -0.5, 0.81])
    light /= np.linalg.norm(light)
    rng = np.random.default_rng(1)
    for normal in [*np.eye(3), *-np.eye(3), *rng.normal(size=(10, 3))]:
        r = RegionRenderer(ctx, _one_triangle(normal), (8, 8), "scissor")
        px = r.render(np.eye(4), np.eye(4), light, (0, 0, 8, 8), None)
        r.release()
        d = abs(float(np.dot(normal / np.linalg.norm(normal), light)))
        assert np.abs(px.astype(int) - 255 * (0.25 + 0.75 * d)).max() <= 1, normal
    ctx.release()
