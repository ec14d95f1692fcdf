"""glTF animation as the specification plays it: node translation, rotation and scale channels.

The file is read through pygltflib (its animations, samplers, accessors, buffers and nodes);
trimesh has already baked each mesh at its node's rest world matrix into the scene, so a body's
map at time ``t`` is ``W(t) W(rest)^-1`` of the node it hangs from (``W``: the node's world
matrix, its ancestors' animated too). Keyframes are sampled the way the specification says:
LINEAR (rotations by slerp, the shorter way), STEP, and CUBICSPLINE (Hermite, tangents scaled by
the keyframe interval, rotations normalized); each animation loops over its own length. Every
channel of every animation played is sampled at once (vectorized over channels; the hierarchy
composed a depth level at a time), so no Python loop runs per node in a frame.

Bad input ends the run at the start with one line naming the file and the field: a channel that
targets a missing node, keyframe times that do not increase or are not finite, an accessor or
buffer view out of range, an animation that does not exist (the model's are listed). Morph
target weights and skins are read as channels but not played: those meshes stand at rest (the
scene's meta says so).
"""

from __future__ import annotations

import base64
from pathlib import Path

import numpy as np

from multigpu.core.motion import bodies_of
from multigpu.errors import InputError

#: the TRS channels played, and the components of each
PATHS = {"translation": 3, "rotation": 4, "scale": 3}
#: numpy dtypes of glTF component types
COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def _bad(path: Path, field: str, what: str) -> InputError:
    return InputError.of("model", f"{path}: {field}: {what}")


def load(path: Path):
    """The pygltflib document of ``path``, or a one-line InputError."""
    import pygltflib

    try:
        return pygltflib.GLTF2().load(str(path))
    except Exception as exc:  # a file trimesh read but pygltflib cannot: say which
        raise _bad(path, "file", f"not a readable glTF ({exc.__class__.__name__})") from None


def accessor(doc, path: Path, index, cache: dict) -> np.ndarray:
    """Accessor ``index`` as a float64 (count, width) array (normalized integers to [0, 1] or
    [-1, 1]), every offset and length checked against its buffer view and buffer."""
    where = f"accessors[{index}]"
    if not isinstance(index, int) or not 0 <= index < len(doc.accessors):
        raise _bad(path, where, f"no such accessor (the file has {len(doc.accessors)})")
    a = doc.accessors[index]
    if a.componentType not in COMPONENTS or a.type not in WIDTH or not isinstance(a.count, int) or a.count < 1:
        raise _bad(path, where, f"unsupported component type {a.componentType}, type {a.type} or count {a.count}")
    if a.bufferView is None or not 0 <= a.bufferView < len(doc.bufferViews):
        raise _bad(path, where, f"bufferView {a.bufferView} does not exist")
    view = doc.bufferViews[a.bufferView]
    data = _buffer(doc, path, view.buffer, cache)
    dtype, width = np.dtype(COMPONENTS[a.componentType]), WIDTH[a.type]
    item = dtype.itemsize * width
    stride = view.byteStride or item
    start = (view.byteOffset or 0) + (a.byteOffset or 0)
    need = start + stride * (a.count - 1) + item
    end = (view.byteOffset or 0) + view.byteLength
    if stride < item or need > end or end > len(data):
        raise _bad(path, where, f"reads bytes {start}..{need} beyond its buffer view (ends at {end}) or buffer "
                                f"({len(data)} bytes)")
    raw = np.lib.stride_tricks.as_strided(np.frombuffer(data, dtype=np.uint8, count=need, offset=0)[start:],
                                          shape=(a.count, item), strides=(stride, 1))
    out = np.ascontiguousarray(raw).view(dtype).reshape(a.count, width).astype(np.float64)
    if a.normalized and dtype.kind in "iu":
        out = np.maximum(out / np.iinfo(dtype).max, -1.0)
    return out


def _buffer(doc, path: Path, index, cache: dict) -> bytes:
    """Buffer ``index``'s bytes: the GLB's own chunk, a data URI, or a file beside ``path``."""
    if index in cache:
        return cache[index]
    if not isinstance(index, int) or not 0 <= index < len(doc.buffers):
        raise _bad(path, f"buffers[{index}]", "does not exist")
    uri = doc.buffers[index].uri
    try:
        if uri is None:
            data = doc.binary_blob() or b""
        elif uri.startswith("data:"):
            data = base64.b64decode(uri.split(",", 1)[1])
        else:
            data = (path.parent / uri).read_bytes()
    except (OSError, ValueError, IndexError) as exc:
        raise _bad(path, f"buffers[{index}]", f"cannot be read ({exc.__class__.__name__})") from None
    cache[index] = data
    return data


def node_matrix(node) -> np.ndarray:
    """A node's local 4x4 matrix at rest: its ``matrix``, else T * R * S."""
    if node.matrix and len(node.matrix) == 16:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
    return trs(np.asarray([node.translation or [0.0, 0, 0]], dtype=np.float64),
               np.asarray([node.rotation or [0.0, 0, 0, 1]], dtype=np.float64),
               np.asarray([node.scale or [1.0, 1, 1]], dtype=np.float64))[0]


def trs(t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(n, 4, 4) matrices T * R * S from (n, 3) translations, (n, 4) xyzw quaternions, (n, 3) scales."""
    q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-300)
    x, y, z, w = q.T
    R = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                  np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                  np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)
    out = np.zeros((len(t), 4, 4))
    out[:, :3, :3] = R * s[:, None, :]
    out[:, :3, 3] = t
    out[:, 3, 3] = 1.0
    return out


def slerp(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(n, 4) spherical interpolation of unit quaternions, the shorter way round."""
    dot = (a * b).sum(axis=1)
    b = np.where(dot[:, None] < 0, -b, b)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(theta)
    near = sin < 1e-6  # nearly the same: linear, then normalized
    wa = np.where(near, 1 - u, np.sin((1 - u) * theta) / np.where(near, 1.0, sin))
    wb = np.where(near, u, np.sin(u * theta) / np.where(near, 1.0, sin))
    out = wa[:, None] * a + wb[:, None] * b
    return out / np.linalg.norm(out, axis=1, keepdims=True)


class Sampler:
    """The keyframes of one node property's channels (one ``path``), all sampled at once: every
    channel's times, values and (CUBICSPLINE) tangents back to back, found with one search."""

    def __init__(self, path: str, nodes: list[int], keys: list[tuple], lengths: list[float]):
        """``keys``: per channel ``(times (k,), values (k, w), in (k, w), out (k, w), mode)``."""
        self.path, self.nodes = path, np.asarray(nodes, dtype=np.int64)
        count = [len(k[0]) for k in keys]
        self.lo = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
        self.hi = self.lo + np.asarray(count) - 1
        self.times = np.concatenate([k[0] for k in keys])
        self.values, self.tin, self.tout = (np.concatenate([k[j] for k in keys]) for j in (1, 2, 3))
        self.step = np.array([k[4] == "STEP" for k in keys])
        self.cubic = np.array([k[4] == "CUBICSPLINE" for k in keys])
        self.first, self.last = self.times[self.lo], self.times[self.hi]
        span = self.last - self.first + 1.0
        ch = np.repeat(np.arange(len(keys)), count)
        self.span = span
        self.keys = ch + (self.times - self.first[ch]) / span[ch]  # increasing over all channels: one search
        self.length = np.asarray(lengths, dtype=np.float64)  # each channel's animation's length: its loop

    def at(self, t: float) -> np.ndarray:
        """(channels, width) every channel's value at time ``t`` (looped over its animation)."""
        loop = np.where(self.length > 0, self.length, 1.0)
        tt = np.clip(np.where(self.length > 0, np.mod(t, loop), 0.0), self.first, self.last)
        query = np.arange(len(self.nodes)) + (tt - self.first) / self.span
        k = np.clip(np.searchsorted(self.keys, query, side="right") - 1, self.lo, np.maximum(self.hi - 1, self.lo))
        k1 = np.minimum(k + 1, self.hi)
        dt = self.times[k1] - self.times[k]
        u = np.where(dt > 0, (tt - self.times[k]) / np.where(dt > 0, dt, 1.0), 0.0)
        u = np.where(self.step, (tt >= self.times[k1]) * 1.0, np.clip(u, 0.0, 1.0))  # STEP: a key holds till the next
        v0, v1 = self.values[k], self.values[k1]
        if self.path == "rotation":
            out = slerp(v0, v1, u)
        else:
            out = v0 + (v1 - v0) * u[:, None]
        if self.cubic.any():  # Hermite between the keyframes, the tangents times the interval
            c = self.cubic
            s = u[c, None]
            s2, s3 = s * s, s * s * s
            h = ((2 * s3 - 3 * s2 + 1) * v0[c] + (s3 - 2 * s2 + s) * self.tout[k[c]] * dt[c, None]
                 + (-2 * s3 + 3 * s2) * v1[c] + (s3 - s2) * self.tin[k1[c]] * dt[c, None])
            out[c] = h / np.linalg.norm(h, axis=1, keepdims=True) if self.path == "rotation" else h
        return out


def targets_of(doc) -> np.ndarray:
    """(n,) how many morph targets each node's mesh has (its primitives' most; 0: none)."""
    per_mesh = [max([len(p.targets or []) for p in m.primitives], default=0) for m in doc.meshes]
    return np.array([per_mesh[nd.mesh] if isinstance(nd.mesh, int) and 0 <= nd.mesh < len(per_mesh) else 0
                     for nd in doc.nodes], dtype=np.int64)


def channels(doc, path: Path, played: list[int]) -> tuple[list[Sampler], set[str]]:
    """The played animations' channels, checked, grouped by property (morph target ``weights`` by
    their count); and the properties read but not played."""
    skipped: set[str] = set()
    cache: dict = {}
    got: dict = {p: ([], [], []) for p in PATHS}
    targets = targets_of(doc)
    for ai in played:  # animations and their channels: read once, at the start
        anim = doc.animations[ai]
        keys = []
        for ci, ch in enumerate(anim.channels):
            where = f"animations[{ai}].channels[{ci}]"
            target = ch.target
            node = getattr(target, "node", None)
            if not isinstance(node, int) or not 0 <= node < len(doc.nodes):
                raise _bad(path, f"{where}.target.node", f"targets node {node}, which does not exist "
                                                          f"(the file has {len(doc.nodes)})")
            if not isinstance(ch.sampler, int) or not 0 <= ch.sampler < len(anim.samplers):
                raise _bad(path, f"{where}.sampler", f"{ch.sampler} is not a sampler of the animation")
            if target.path not in (*PATHS, "weights"):
                skipped.add(str(target.path))
                keys.append(None)
                continue
            if target.path == "weights" and not targets[node]:
                raise _bad(path, f"{where}.target.path", f"animates the weights of node {node}, whose mesh has no "
                                                          "morph targets")
            s = anim.samplers[ch.sampler]
            where = f"animations[{ai}].samplers[{ch.sampler}]"
            times = accessor(doc, path, s.input, cache)[:, 0]
            if not np.isfinite(times).all() or (np.diff(times) <= 0).any():
                raise _bad(path, f"{where}.input", "keyframe times must be finite and increasing")
            mode = s.interpolation or "LINEAR"
            if mode not in ("LINEAR", "STEP", "CUBICSPLINE"):
                raise _bad(path, f"{where}.interpolation", f"'{mode}' is not LINEAR, STEP or CUBICSPLINE")
            values = accessor(doc, path, s.output, cache)
            w, per = PATHS.get(target.path, int(targets[node])), 3 if mode == "CUBICSPLINE" else 1
            if target.path == "weights":  # scalars, one per target a keyframe
                values = values.reshape(-1, w) if values.shape[1] == 1 and values.size % w == 0 else values
            if values.shape != (per * len(times), w) or not np.isfinite(values).all():
                raise _bad(path, f"{where}.output", f"holds {values.shape[0]} finite values of {values.shape[1]}; "
                                                    f"{per * len(times)} of {w} wanted")
            if per == 3:
                tin, values, tout = values[0::3], values[1::3], values[2::3]
            else:
                tin = tout = np.zeros_like(values)
            key = ("weights", w) if target.path == "weights" else target.path
            keys.append((key, node, (times, values, tin, tout, mode)))
        length = max([k[2][0][-1] for k in keys if k is not None], default=0.0)
        for k in keys:
            if k is not None:
                nodes, ks, lengths = got.setdefault(k[0], ([], [], []))
                nodes.append(k[1])
                ks.append(k[2])
                lengths.append(length)
    return [Sampler(p if isinstance(p, str) else p[0], *got[p]) for p in got if got[p][0]], skipped



def check(path: Path) -> None:
    """Every animation of the glTF file at ``path`` read and checked (before trimesh reads its
    meshes: a broken accessor is then named by its field), where it has any."""
    doc = load(path)
    if doc.animations:
        channels(doc, path, list(range(len(doc.animations))))


def _levels(parent: np.ndarray) -> list[np.ndarray]:
    """The nodes a depth at a time, roots first (``parent`` -1 for a root)."""
    depth = np.zeros(len(parent), dtype=np.int64)
    at = parent.copy()
    for _ in range(len(parent) + 1):  # depth levels, bounded: a cycle was refused before
        live = at >= 0
        if not live.any():
            break
        depth[live] += 1
        at[live] = parent[at[live]]
    return [np.flatnonzero(depth == d) for d in range(int(depth.max()) + 1)] if len(parent) else []


def hierarchy(doc, path: Path) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """(parent (n,), the nodes a depth level at a time, rest local matrices (n, 4, 4)), checked:
    a child named twice, by itself or out of range, and cycles, are refused."""
    n = len(doc.nodes)
    parent = np.full(n, -1, dtype=np.int64)
    for i, node in enumerate(doc.nodes):  # the model's nodes, read once
        for c in node.children or []:
            if not isinstance(c, int) or not 0 <= c < n or parent[c] >= 0 or c == i:
                raise _bad(path, f"nodes[{i}].children", f"names node {c}, not a node of its own")
            parent[c] = i
    levels = _levels(parent)
    if sum(len(lv) for lv in levels) != n:
        raise _bad(path, "nodes", "the node hierarchy has a cycle")
    rest = np.stack([node_matrix(node) for node in doc.nodes]) if n else np.zeros((0, 4, 4))
    return parent, levels, rest


def world_of(local: np.ndarray, parent: np.ndarray, levels: list[np.ndarray]) -> np.ndarray:
    """(n, 4, 4) world matrices from local ones, a depth level at a time."""
    world = local.copy()
    for lv in levels[1:]:
        world[lv] = world[parent[lv]] @ local[lv]
    return world


def palette_of(doc, path: Path) -> tuple[list[int], np.ndarray]:
    """The skinned nodes (those with a ``skin``) and where each one's joints start in the palette
    (``GltfMotion``: one block of joint matrices per skinned node), every skin checked."""
    nodes = [i for i, nd in enumerate(doc.nodes) if getattr(nd, "skin", None) is not None]
    sizes = []
    for i in nodes:  # skinned nodes: a few
        s = doc.nodes[i].skin
        if not isinstance(s, int) or not 0 <= s < len(doc.skins):
            raise _bad(path, f"nodes[{i}].skin", f"names skin {s}, which does not exist (the file has "
                                                   f"{len(doc.skins)})")
        joints = doc.skins[s].joints or []
        if not joints or any(not isinstance(j, int) or not 0 <= j < len(doc.nodes) for j in joints):
            raise _bad(path, f"skins[{s}].joints", f"must name nodes of the file ({len(doc.nodes)}), got {joints[:8]}")
        sizes.append(len(joints))
    return nodes, np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)


def rest_world(doc, path: Path) -> np.ndarray:
    """(n, 4, 4) every node's world matrix at rest."""
    parent, levels, rest = hierarchy(doc, path)
    return world_of(rest, parent, levels)


class GltfMotion:
    """A glTF file's node animations as a ``core.motion.Motion`` of the scene loaded from it
    (``scene.meta['gltf']``: the file and the node each modelled object hangs from)."""

    def __init__(self, scene, which: str = "all"):
        info = scene.meta["gltf"]
        self.path = path = Path(info["file"])
        doc = load(path)
        self.bodies = bodies_of(scene)
        body_node = np.asarray(info["nodes"], dtype=np.int64)
        n = len(doc.nodes)
        self.names = [a.name or f"animation {i}" for i, a in enumerate(doc.animations)]
        played = [] if which == "none" else list(range(len(self.names))) if which == "all" else [
            i for i, name in enumerate(self.names) if name == which]
        if which not in ("all", "none") and not played:
            raise InputError.of("animation", f"'{which}': {path} has no such animation (it has: "
                                f"{', '.join(repr(x) for x in self.names) or 'none'})")
        self.parent, self.levels, self.rest = hierarchy(doc, path)
        self.fixed = np.array([bool(node.matrix) and len(node.matrix) == 16 for node in doc.nodes])
        self.trs = (np.array([node.translation or [0.0, 0, 0] for node in doc.nodes], dtype=np.float64).reshape(n, 3),
                    np.array([node.rotation or [0.0, 0, 0, 1] for node in doc.nodes], dtype=np.float64).reshape(n, 4),
                    np.array([node.scale or [1.0, 1, 1] for node in doc.nodes], dtype=np.float64).reshape(n, 3))
        self.samplers, self.skipped = channels(doc, path, played)  # skipped: read, not played (morph weights)
        animated, morphed = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        for s in self.samplers:
            (morphed if s.path == "weights" else animated)[s.nodes] = True
        for lv in self.levels[1:]:  # a node moves where an ancestor does
            animated[lv] |= animated[self.parent[lv]]
        self._morphs(doc, body_node)
        animated |= morphed  # a mesh whose weights play moves too (its own vertices, not its children)
        if body_node.size and (body_node.min() < 0 or body_node.max() >= n):
            raise _bad(path, "nodes", "the scene cache names a node the file does not have (rebuild the cache)")
        self.node = body_node
        self.moving = animated[body_node] if body_node.size else np.zeros(0, dtype=bool)
        self._skins(doc, path, body_node, animated)
        self.rest_inverse = np.linalg.inv(self._world(self.rest)[body_node])
        self.o = np.asarray(scene.origin, dtype=np.float64) - np.asarray(scene.meta.get("offset", 0.0))

    def _morphs(self, doc, body_node: np.ndarray) -> None:
        """Each morphing node's slots in the weight vector (``slot``), their values at rest (the
        node's ``weights``, else its mesh's, else 0), and each body's (first slot, count)."""
        count = targets_of(doc)
        count[[i for i, nd in enumerate(doc.nodes) if getattr(nd, "skin", None) is not None]] = 0  # its skin alone
        self.slot = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
        rest = np.zeros(int(count.sum()))
        for i in np.flatnonzero(count):  # the morphing nodes, read once
            node = doc.nodes[i]
            given = getattr(node, "weights", None) or getattr(doc.meshes[node.mesh], "weights", None) or []
            given = np.asarray(given, dtype=np.float64)[:count[i]]
            rest[self.slot[i]:self.slot[i] + len(given)] = given
        self.rest_weights, self.last_weights = rest, rest.copy()
        self.morph_of = np.stack([self.slot[body_node], count[body_node]], axis=1).astype(np.int32).reshape(-1, 2)

    def _skins(self, doc, path: Path, body_node: np.ndarray, animated: np.ndarray) -> None:
        """The joint palette (``palette``: joint nodes, inverse bind matrices, the skinned node's
        rest world inverse), and which bodies are skinned (``skinned``: their node's own transform
        is not applied, as the specification says; they move where a joint does)."""
        nodes, start = palette_of(doc, path)
        joints, ibm, mesh_inv, cache = [], [], [], {}
        world = self._world(self.rest)
        for i in nodes:  # skinned nodes: a few
            s = doc.nodes[i].skin
            js = doc.skins[s].joints
            if doc.skins[s].inverseBindMatrices is None:
                m = np.tile(np.eye(4), (len(js), 1, 1))
            else:
                m = accessor(doc, path, doc.skins[s].inverseBindMatrices, cache)
                if m.shape != (len(js), 16) or not np.isfinite(m).all():
                    raise _bad(path, f"skins[{s}].inverseBindMatrices", f"holds {m.shape[0]} matrices of "
                                                                         f"{m.shape[1]}; {len(js)} of 16 wanted")
                m = m.reshape(-1, 4, 4).transpose(0, 2, 1)  # column-major
            joints += list(js)
            ibm.append(m)
            mesh_inv.append(np.tile(np.linalg.inv(world[i]), (len(js), 1, 1)))
        self.skinned = np.isin(body_node, nodes) if nodes else np.zeros(len(body_node), dtype=bool)
        self.palette = None
        if nodes:
            self.palette = (np.asarray(joints, dtype=np.int64), np.concatenate(ibm), np.concatenate(mesh_inv))
            moves = any(animated[doc.skins[doc.nodes[i].skin].joints].any() for i in nodes)
            self.moving = self.moving | (self.skinned & moves)
        self.last_palette = None

    def _world(self, local: np.ndarray) -> np.ndarray:
        return world_of(local, self.parent, self.levels)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        T, R, S = (a.copy() for a in self.trs)
        weights = self.rest_weights.copy()
        for s in self.samplers:  # translation, rotation, scale, weights
            if s.path == "weights":
                got = s.at(t)
                weights[self.slot[s.nodes][:, None] + np.arange(got.shape[1])] = got
                continue
            {"translation": T, "rotation": R, "scale": S}[s.path][s.nodes] = s.at(t)
        self.last_weights = weights  # the morph targets' weights at ``t`` (``Posed``, the renderer)
        local = trs(T, R, S)
        local[self.fixed] = self.rest[self.fixed]  # a node given by its matrix is not animated
        world = self._world(local)
        M = world[self.node] @ self.rest_inverse  # the node's map, world to world
        M[self.skinned] = np.eye(4)  # a skinned mesh moves by its joints alone (``last_palette``)
        if self.palette is not None:
            joints, ibm, mesh_inv = self.palette
            self.last_palette = self._local(world[joints] @ ibm @ mesh_inv)
        return self._local(M)

    def _local(self, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World-to-world maps as maps of the scene's local coordinates (about its origin)."""
        A = np.ascontiguousarray(M[:, :3, :3])
        return A, M[:, :3, 3] + np.einsum("nij,j->ni", A, self.o) - self.o
