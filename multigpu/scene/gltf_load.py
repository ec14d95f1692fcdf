"""What a glTF file's animation needs from loading: each object's node, and its morph targets.

trimesh bakes every mesh at its node's rest world matrix and leaves animation and morph targets
out; this module reads them through pygltflib (``gltf_motion``) beside it. ``mesh_deltas``
gives each dumped mesh's morph target position deltas, turned into world space by its node's rest
matrix (matched to its primitive by vertex count and position); ``pack`` keeps them sparse in the
scene (a row per vertex that morphs) with each object's extent of every target's deltas (its
bounds, grown by the frame's weights: ``core.motion.Posed``); ``animated`` records the nodes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.scene.blocks import per_object
from multigpu.scene.gltf_motion import _bad, accessor, load, palette_of, rest_world


def mesh_deltas(path: Path, meshes, nodes: list[int] | None) -> list | None:
    """Per dumped mesh (``nodes``: each one's glTF node), its (V, T, 3) world-space morph deltas
    or None; None where the file has no morph targets (or no animation to play them)."""
    if nodes is None:
        return None
    doc = load(path)
    if not any(p.targets for m in doc.meshes for p in m.primitives):
        return None
    world, cache, out = rest_world(doc, path), {}, []
    for mesh, node in zip(meshes, nodes):  # meshes: a model's parts, read once at load
        pos, got = np.asarray(mesh.vertices, dtype=np.float64), None
        mi = doc.nodes[node].mesh
        for pi, prim in enumerate(doc.meshes[mi].primitives if mi is not None else []):
            if not prim.targets or prim.attributes.POSITION is None:
                continue
            base = accessor(doc, path, prim.attributes.POSITION, cache)
            W = world[node]
            scale = max(float(np.abs(pos).max()), 1e-30)
            if len(base) != len(pos) or not np.allclose(base @ W[:3, :3].T + W[:3, 3], pos, atol=1e-6 * scale):
                continue
            got = np.zeros((len(pos), len(prim.targets), 3))
            for k, target in enumerate(prim.targets):
                at = target.get("POSITION") if isinstance(target, dict) else getattr(target, "POSITION", None)
                if at is None:  # a target of normals alone moves no vertex
                    continue
                where = f"meshes[{mi}].primitives[{pi}].targets[{k}].POSITION"
                delta = accessor(doc, path, at, cache)
                if delta.shape != (len(pos), 3) or not np.isfinite(delta).all():
                    raise _bad(path, where, f"holds {delta.shape[0]} finite deltas of {delta.shape[1]}; the primitive "
                                            f"has {len(pos)} vertices")
                got[:, k] = delta @ W[:3, :3].T
            break
        out.append(got)
    return out if any(d is not None for d in out) else None


def joined(deltas: list, sizes) -> np.ndarray:
    """The meshes' deltas back to back over their vertices, (V, T, 3) float32 (zeros where none)."""
    T = max(d.shape[1] for d in deltas if d is not None)
    out = np.zeros((int(np.sum(sizes)), T, 3), dtype=np.float32)
    at = 0
    for d, n in zip(deltas, sizes):  # meshes
        if d is not None:
            out[at:at + n, :d.shape[1]] = d
        at += n
    return out


def pack(morph: np.ndarray, used: np.ndarray, sorted_blocks, n: int) -> dict:
    """The scene's morph arrays from (V, T, 3) deltas of the model's vertices: ``morph_rows`` (V',)
    int32 each kept vertex's row (-1: it does not morph), ``morph_deltas`` (M, T, 3) float32, and
    ``morph_lo``/``morph_hi`` (N, T, 3) each object's least and greatest delta per target (0 held)."""
    kept = morph[used]
    moves = np.abs(kept).reshape(len(kept), -1).max(axis=1) > 0
    rows = np.full(len(used), -1, dtype=np.int32)
    rows[moves] = np.arange(int(moves.sum()), dtype=np.int32)
    T = morph.shape[1]
    lo, hi = np.zeros((n, T, 3)), np.zeros((n, T, 3))
    for _, _, f, lab in sorted_blocks():
        d = morph[f]  # (b, 3, T, 3)
        per_object(np.minimum, d.min(axis=1), lab, lo)
        per_object(np.maximum, d.max(axis=1), lab, hi)
    return {"morph_rows": rows, "morph_deltas": np.ascontiguousarray(kept[moves], dtype=np.float32),
            "morph_lo": lo, "morph_hi": hi}


def animated(scene, path: Path, nodes: list[int] | None, split: str):
    """The scene with the glTF node each object hangs from (``meta['gltf']``, read by
    ``gltf_motion.GltfMotion``), where the file has animations; an explicit ``--split`` cuts
    across nodes, so the model then stands still (its meta says why)."""
    if nodes is None and "gltf_nodes" not in scene.meta:
        return scene
    doc = load(path)
    names = [a.name or f"animation {i}" for i, a in enumerate(doc.animations)]
    scene.meta["warnings"].extend(not_played(doc))
    per = scene.meta.pop("gltf_nodes", nodes)
    if split != "auto" or per is None or len(per) != scene.n_objects:
        scene.meta["warnings"].append(f"animations ({', '.join(names)}) not played: --split {split} cuts objects "
                                      "across the model's nodes (use --split auto)")
        return scene
    scene.meta["gltf"] = {"file": str(Path(path).resolve()), "nodes": [int(n) for n in per], "animations": names}
    return scene



def mesh_skins(path: Path, meshes, nodes: list[int] | None) -> tuple | None:
    """Per vertex of the dumped meshes back to back: (V, 4) palette joints and (V, 4) weights (0
    where a vertex is not skinned); None where the file has no skin to play."""
    if nodes is None:
        return None
    doc = load(path)
    if not doc.skins:
        return None
    skinned, start = palette_of(doc, path)
    world, cache = rest_world(doc, path), {}
    total = sum(len(m.vertices) for m in meshes)
    joints, weights = np.zeros((total, 4), dtype=np.uint16), np.zeros((total, 4), dtype=np.float32)
    at = 0
    for mesh, node in zip(meshes, nodes):  # meshes: a model's parts, read once at load
        pos, mi = np.asarray(mesh.vertices, dtype=np.float64), doc.nodes[node].mesh
        if node in skinned and mi is not None:
            s = doc.nodes[node].skin
            for pi, prim in enumerate(doc.meshes[mi].primitives):
                a = prim.attributes
                if a.JOINTS_0 is None or a.WEIGHTS_0 is None or a.POSITION is None:
                    continue
                base, W = accessor(doc, path, a.POSITION, cache), world[node]
                scale = max(float(np.abs(pos).max()), 1e-30)
                if len(base) != len(pos) or not np.allclose(base @ W[:3, :3].T + W[:3, 3], pos, atol=1e-6 * scale):
                    continue
                where = f"meshes[{mi}].primitives[{pi}].attributes"
                j, w = accessor(doc, path, a.JOINTS_0, cache), accessor(doc, path, a.WEIGHTS_0, cache)
                n_joints = len(doc.skins[s].joints)
                if j.shape != (len(pos), 4) or (j >= n_joints).any() or (j < 0).any():
                    raise _bad(path, f"{where}.JOINTS_0", f"joint index {int(j.max())} exceeds skin {s}'s {n_joints} "
                                                          f"joints (or not one per vertex)")
                if w.shape != (len(pos), 4) or not np.isfinite(w).all() or (w < 0).any():
                    raise _bad(path, f"{where}.WEIGHTS_0", "must be 4 finite weights >= 0 per vertex")
                total_w = w.sum(axis=1, keepdims=True)
                w = w / np.where(total_w > 0, total_w, 1.0)  # they sum to 1
                joints[at:at + len(pos)] = j.astype(np.int64) + start[skinned.index(node)]
                weights[at:at + len(pos)] = w
                break
        at += len(pos)
    return (joints, weights) if weights.any() else None


def skin_pack(joints: np.ndarray, weights: np.ndarray, verts: np.ndarray, used: np.ndarray, sorted_blocks) -> dict:
    """The scene's skin arrays: ``skin_joints``/``skin_weights`` (V', 4) of the kept vertices, and
    for every (object, joint) a vertex of the object leans on, the box of those vertices
    (``skin_pairs`` (P, 2), ``skin_boxes`` (P, 6) world min and max): a pose's bounds are the union
    of each pair's box moved by its joint (a vertex is a weighted mean of its joints' images)."""
    keys, pts = [], []
    for _, _, f, lab in sorted_blocks():  # blocks of faces
        v = f.ravel()
        owner = np.repeat(lab, 3)
        for i in range(4):  # a vertex's four influences
            on = weights[v, i] > 0
            keys.append(owner[on] * (int(joints.max()) + 1) + joints[v[on], i])
            pts.append(verts[v[on]])
    keys, pts = np.concatenate(keys), np.concatenate(pts)
    uniq, inv = np.unique(keys, return_inverse=True)
    lo, hi = np.full((len(uniq), 3), np.inf), np.full((len(uniq), 3), -np.inf)
    np.minimum.at(lo, inv, pts)
    np.maximum.at(hi, inv, pts)
    width = int(joints.max()) + 1
    return {"skin_joints": np.ascontiguousarray(joints[used]), "skin_weights": np.ascontiguousarray(weights[used]),
            "skin_pairs": np.stack([uniq // width, uniq % width], axis=1).astype(np.int64),
            "skin_boxes": np.concatenate([lo, hi], axis=1)}


def not_played(doc) -> list[str]:
    """What of a file's animation is not played, one warning line each: a mesh both skinned and
    morphed plays its skin alone."""
    both = [i for i, nd in enumerate(doc.nodes) if getattr(nd, "skin", None) is not None and nd.mesh is not None
            and any(p.targets for p in doc.meshes[nd.mesh].primitives)]
    return [f"node {i}: skinned and morphed: its morph targets are not played" for i in both]


def nodes_of(path: Path, loaded, meshes) -> list[int] | None:
    """The glTF node each dumped mesh (``Scene.dump``'s, in order) hangs from, where the file has
    animations (None otherwise): trimesh names its graph's nodes as its glTF loader does
    (``unique_name`` over the nodes in order), a primitive's frame under its node's."""
    from trimesh.util import unique_name

    from multigpu.scene.textures import gltf_json

    doc = gltf_json(path)
    if not doc or not doc.get("animations"):
        return None
    index: dict = {}
    counts: dict = {}
    for i, node in enumerate(doc.get("nodes", [])):
        index[unique_name(node.get("name", str(i)), index, counts=counts)] = i
    parents = loaded.graph.transforms.parents
    out = []
    for m in meshes:
        name = m.metadata.get("node")
        got = index.get(name, index.get(parents.get(name)))
        if got is None:
            return None
        out.append(int(got))
    return out
