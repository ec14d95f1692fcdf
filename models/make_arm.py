"""Write models/arm.glb: a skinned arm (glTF 2.0, +Y up, metres) that waves, made with pygltflib.

One mesh, a tube two metres long up +Y (24 sides, a ring every 5 cm), skinned to two joints: the
shoulder at the foot and the elbow a metre up; the rings near the elbow lean on both (weights
blend over 40 cm), so the tube bends smoothly. One animation, "wave": the elbow bends 100 degrees
and back (LINEAR rotations, slerp) while the shoulder sways (CUBICSPLINE rotations), 2 s, looped.
Deterministic; run ``python models/make_arm.py`` to remake it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib as g

HERE = Path(__file__).resolve().parent
SIDES, RINGS, LENGTH, RADIUS = 24, 41, 2.0, 0.12


def tube() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, normals (V, 3) and triangle indices of the tube, rings from the foot up."""
    a = 2 * np.pi * np.arange(SIDES) / SIDES
    y = np.linspace(0.0, LENGTH, RINGS)
    ring = np.stack([np.cos(a), np.zeros(SIDES), np.sin(a)], axis=1)
    pos = (ring[None] * RADIUS + y[:, None, None] * np.array([0.0, 1.0, 0.0])).reshape(-1, 3)
    nrm = np.tile(ring, (RINGS, 1))
    r, s = np.meshgrid(np.arange(RINGS - 1), np.arange(SIDES), indexing="ij")
    p, q = r * SIDES + s, r * SIDES + (s + 1) % SIDES
    idx = np.stack([p, p + SIDES, q, q, p + SIDES, q + SIDES], axis=-1).reshape(-1)
    return pos.astype(np.float32), nrm.astype(np.float32), idx.astype(np.uint16)


def weights(pos: np.ndarray) -> np.ndarray:
    """(V, 4) each vertex's lean on the shoulder and the elbow (blended 0.8 m to 1.2 m up)."""
    elbow = np.clip((pos[:, 1] - 0.8) / 0.4, 0.0, 1.0)
    return np.stack([1 - elbow, elbow, 0 * elbow, 0 * elbow], axis=1).astype(np.float32)


def _quat(axis, degrees) -> np.ndarray:
    h = np.radians(np.asarray(degrees, dtype=np.float64)) / 2
    return np.array([[*(np.sin(x) * np.asarray(axis, dtype=np.float64)), np.cos(x)] for x in h], dtype=np.float32)


def main() -> Path:
    pos, nrm, idx = tube()
    joints = np.tile(np.array([0, 1, 0, 0], dtype=np.uint16), (len(pos), 1))
    ibm = np.stack([np.eye(4), np.linalg.inv(np.array([[1, 0, 0, 0], [0, 1, 0, 1.0], [0, 0, 1, 0], [0, 0, 0, 1]]))])
    bend = np.array([0.0, 100.0, 0.0])
    sway = _quat([1, 0, 0], [0.0, 15.0, 0.0])
    arrays = [(idx, g.UNSIGNED_SHORT, g.SCALAR), (pos, g.FLOAT, g.VEC3), (nrm, g.FLOAT, g.VEC3),
              (joints, g.UNSIGNED_SHORT, g.VEC4), (weights(pos), g.FLOAT, g.VEC4),
              (ibm.transpose(0, 2, 1).reshape(2, 16).astype(np.float32), g.FLOAT, g.MAT4),  # column-major
              (np.array([0.0, 1.0, 2.0], dtype=np.float32), g.FLOAT, g.SCALAR),
              (_quat([0, 0, 1], bend), g.FLOAT, g.VEC4),
              (np.concatenate([[np.zeros(4), q, np.zeros(4)] for q in sway]).astype(np.float32), g.FLOAT, g.VEC4)]
    blob, views, accessors = bytearray(), [], []
    for data, kind, shape in arrays:  # a buffer view and an accessor each
        while len(blob) % 4:
            blob.append(0)
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=data.nbytes))
        flat = data.reshape(len(data), -1)
        accessors.append(g.Accessor(bufferView=len(views) - 1, componentType=kind, count=len(data), type=shape,
                                    min=flat.min(axis=0).tolist() if len(accessors) in (1, 6) else None,
                                    max=flat.max(axis=0).tolist() if len(accessors) in (1, 6) else None))
        blob.extend(data.tobytes())
    sampler = lambda inp, out, mode: g.AnimationSampler(input=inp, output=out, interpolation=mode)  # noqa: E731
    channel = lambda s, node: g.AnimationChannel(sampler=s, target=g.AnimationChannelTarget(node=node,  # noqa: E731
                                                                                             path="rotation"))
    doc = g.GLTF2(
        scene=0, scenes=[g.Scene(nodes=[0, 1])],
        nodes=[g.Node(name="arm", mesh=0, skin=0), g.Node(name="shoulder", children=[2]),
               g.Node(name="elbow", translation=[0.0, 1.0, 0.0])],
        meshes=[g.Mesh(name="arm", primitives=[g.Primitive(
            attributes=g.Attributes(POSITION=1, NORMAL=2, JOINTS_0=3, WEIGHTS_0=4), indices=0, material=0)])],
        materials=[g.Material(name="skin", pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=[0.85, 0.62, 0.48, 1.0], metallicFactor=0.0, roughnessFactor=0.8))],
        skins=[g.Skin(joints=[1, 2], inverseBindMatrices=5)],
        animations=[g.Animation(name="wave", samplers=[sampler(6, 7, "LINEAR"), sampler(6, 8, "CUBICSPLINE")],
                                channels=[channel(0, 2), channel(1, 1)])],
        accessors=accessors, bufferViews=views, buffers=[g.Buffer(byteLength=len(blob))])
    doc.set_binary_blob(bytes(blob))
    out = HERE / "arm.glb"
    doc.save_binary(str(out))
    return out


if __name__ == "__main__":
    path = main()
    print(f"wrote {path} ({path.stat().st_size} bytes)")
