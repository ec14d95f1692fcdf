"""Write models/pump.glb: a small pump assembly (glTF 2.0, +Y up, metres), made of trimesh
primitives, one node per part; and models/pump-running.glb, the same pump with two animations
(``animate``: pygltflib). Deterministic; run ``python models/make_pump.py`` to remake them.

It is the kind of model users bring (a CAD assembly exported to glTF): compact, a few big
parts (base, casing, motor) among many small ones (bolts, flanges, pipe segments), each part but
the base of one of five materials (``MATERIALS``: glTF ``baseColorFactor``); the base plate is a steel
tread plate (a small repeated texture, ``tread``: glTF ``baseColorTexture``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from PIL import Image
from trimesh.transformations import rotation_matrix, translation_matrix
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

HERE = Path(__file__).resolve().parent
#: the parts' materials (glTF baseColorFactor, RGBA 0-255): a grey cast casing and base, an
#: orange motor, blue pipework, steel bolts, a red gauge
MATERIALS = {"cast": [150, 152, 158, 255], "motor": [226, 110, 24, 255], "pipe": [40, 86, 180, 255],
             "steel": [200, 200, 196, 255], "gauge": [200, 30, 30, 255]}


def material_of(name: str) -> str:
    """The material a part is made of, by its name."""
    if name.startswith(("motor", "fan_cover", "fin_", "coupling")):
        return "motor"
    if name.startswith(("pipe_", "inlet", "outlet", "flange_")) and "bolt" not in name:
        return "pipe"
    if "bolt" in name:
        return "steel"
    return "gauge" if name == "gauge" else "cast"


def tread(size: int = 32) -> Image.Image:
    """A steel tread plate's pattern: raised diagonal bars on a grey plate, ``size`` pixels square,
    repeating at its edges (the base's texture, wrapped several times across it)."""
    y, x = np.indices((size, size)) / size
    bar = lambda u, v: (np.abs(u - 0.5) < 0.32) & (np.abs(v - 0.5) < 0.07)
    a, b = (x + y) % 1.0, (x - y) % 1.0
    raised = bar((x * 2) % 1.0, ((x + y) * 2) % 1.0) | bar((y * 2) % 1.0, (b * 2) % 1.0)
    grey = np.where(raised, 235, 170) - (a * 10).astype(int)
    return Image.fromarray(np.repeat(grey[..., None], 3, axis=2).astype(np.uint8), "RGB")


def _at(mesh: trimesh.Trimesh, xyz, rot=None) -> trimesh.Trimesh:
    if rot is not None:
        mesh.apply_transform(rotation_matrix(np.radians(rot[0]), rot[1]))
    mesh.apply_transform(translation_matrix(xyz))
    return mesh


def parts() -> dict[str, trimesh.Trimesh]:
    """Name -> part, in metres, +Y up (glTF's convention)."""
    x, z = [1, 0, 0], [0, 0, 1]
    p = {"base": _at(trimesh.creation.box([1.6, 0.08, 0.7]), [0, 0.04, 0])}
    p["motor"] = _at(trimesh.creation.cylinder(0.18, 0.6, sections=48), [-0.45, 0.3, 0], (90, z))
    p["fan_cover"] = _at(trimesh.creation.cylinder(0.2, 0.08, sections=48), [-0.79, 0.3, 0], (90, z))
    p["coupling"] = _at(trimesh.creation.cylinder(0.07, 0.16, sections=32), [-0.07, 0.3, 0], (90, z))
    p["casing"] = _at(trimesh.creation.icosphere(subdivisions=3, radius=0.24), [0.28, 0.3, 0])
    p["volute"] = _at(trimesh.creation.torus(0.22, 0.06, major_sections=48, minor_sections=16), [0.28, 0.3, 0], (90, z))
    p["inlet"] = _at(trimesh.creation.cylinder(0.08, 0.5, sections=32), [0.7, 0.3, 0], (90, z))
    p["outlet"] = _at(trimesh.creation.cylinder(0.07, 0.5, sections=32), [0.28, 0.72, 0])
    for i, (pos, rot) in enumerate([([0.95, 0.3, 0], (90, z)), ([0.28, 0.97, 0], None)]):
        p[f"flange_{i}"] = _at(trimesh.creation.cylinder(0.13, 0.03, sections=40), pos, rot)
    for i, (px, pz) in enumerate([(-0.7, -0.25), (-0.7, 0.25), (-0.2, -0.25), (-0.2, 0.25),
                                  (0.1, -0.25), (0.1, 0.25), (0.5, -0.25), (0.5, 0.25)]):
        p[f"foot_bolt_{i}"] = _at(trimesh.creation.cylinder(0.02, 0.06, sections=12), [px, 0.11, pz], (90, x))
    rng = np.random.default_rng(7)
    for f, (cx, cy, rot) in enumerate([(0.95, 0.3, (90, z)), (0.28, 0.97, None)]):
        for k in range(8):  # bolt circle on each flange
            a = 2 * np.pi * k / 8
            off = [0, 0.1 * np.cos(a), 0.1 * np.sin(a)] if rot else [0.1 * np.cos(a), 0, 0.1 * np.sin(a)]
            p[f"flange_{f}_bolt_{k}"] = _at(trimesh.creation.cylinder(0.012, 0.05, sections=10),
                                           [cx + off[0], cy + off[1], off[2]], rot)
    for k in range(12):  # motor cooling fins
        a = 2 * np.pi * k / 12
        p[f"fin_{k}"] = _at(trimesh.creation.box([0.56, 0.02, 0.05]),
                            [-0.45, 0.3 + 0.19 * np.cos(a), 0.19 * np.sin(a)], (np.degrees(-a), x))
    for k in range(6):  # a pipe run leaving the outlet
        pipe = trimesh.creation.cylinder(0.07, 0.3, sections=32)
        p[f"pipe_{k}"] = _at(pipe, [0.28 + 0.3 * (k + 0.5), 1.1, 0], (90, z))
    p["gauge"] = _at(trimesh.creation.cylinder(0.05, 0.02, sections=24), [0.28, 0.86, 0.09 + rng.uniform(0, 1e-3)],
                     (90, x))
    return p


def main() -> Path:
    scene = trimesh.Scene()
    materials = {k: PBRMaterial(name=k, baseColorFactor=v, metallicFactor=0.0, roughnessFactor=0.8)
                 for k, v in MATERIALS.items()}
    for name, mesh in parts().items():
        if name == "base":  # the tread plate repeats every 0.2 m across the base (REPEAT: glTF's default)
            plate = PBRMaterial(name="tread", baseColorTexture=tread(), baseColorFactor=[255, 255, 255, 255],
                                metallicFactor=0.0, roughnessFactor=0.8)
            mesh.visual = TextureVisuals(uv=mesh.vertices[:, [0, 2]] / 0.2, material=plate)
        else:
            mesh.visual = TextureVisuals(material=materials[material_of(name)])
        scene.add_geometry(mesh, node_name=name, geom_name=name)
    out = HERE / "pump.glb"
    out.write_bytes(scene.export(file_type="glb"))
    return out


#: the running pump's moving groups: a pivot node (its place) over these parts
GROUPS = {"rotor": ([-0.45, 0.3, 0.0], [f"fin_{k}" for k in range(12)]),
          "gauge_pivot": ([0.28, 0.86, 0.09], ["gauge"]),
          "bolt_ring": ([0.28, 0.97, 0.0], [f"flange_1_bolt_{k}" for k in range(8)]),
          "pipe_run": ([0.0, 0.0, 0.0], [*(f"pipe_{k}" for k in range(6))])}


def _quat(axis, degrees) -> list[list[float]]:
    """xyzw quaternions turning ``degrees`` (each) about unit ``axis``."""
    h = np.radians(np.asarray(degrees, dtype=np.float64)) / 2
    return [[*(np.sin(a) * np.asarray(axis, dtype=np.float64)), np.cos(a)] for a in h]


def animate(src: Path, out: Path) -> Path:
    """``src`` with each of ``GROUPS`` hung from a pivot node and two animations: "run" (the cooling
    fins' cage turning about its axis, LINEAR rotations by slerp; the gauge pulsing, CUBICSPLINE
    scale; the top flange's bolt ring stepping round, STEP rotation) and "lift" (the pipe run
    rising and settling, LINEAR translation), 2 s each, looped."""
    import pygltflib as g

    doc = g.GLTF2().load(str(src))
    blob = bytearray(doc.binary_blob())
    by_name = {n.name: i for i, n in enumerate(doc.nodes)}
    roots = doc.scenes[doc.scene or 0].nodes

    def data(values, kind: str) -> int:
        arr = np.asarray(values, dtype=np.float32)
        while len(blob) % 4:
            blob.append(0)
        doc.bufferViews.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=arr.nbytes))
        blob.extend(arr.tobytes())
        flat = arr.reshape(len(arr), -1)
        doc.accessors.append(g.Accessor(bufferView=len(doc.bufferViews) - 1, componentType=g.FLOAT, count=len(arr),
                                        type=kind, min=flat.min(axis=0).tolist() if kind == "SCALAR" else None,
                                        max=flat.max(axis=0).tolist() if kind == "SCALAR" else None))
        return len(doc.accessors) - 1

    pivot = {}
    for name, (at, members) in GROUPS.items():  # a pivot at ``at``, its parts moved back under it
        kids = [by_name[m] for m in members]
        for k in kids:
            doc.nodes[k].translation = [-v for v in at]
            roots.remove(k)
        doc.nodes.append(g.Node(name=name, translation=list(at), children=kids))
        pivot[name] = len(doc.nodes) - 1
        roots.append(pivot[name])

    def channel(anim, node: int, path: str, times, values, kind: str, mode: str) -> None:
        anim.samplers.append(g.AnimationSampler(input=data(times, "SCALAR"), output=data(values, kind),
                                                interpolation=mode))
        anim.channels.append(g.AnimationChannel(sampler=len(anim.samplers) - 1,
                                                target=g.AnimationChannelTarget(node=node, path=path)))

    run, lift = g.Animation(name="run"), g.Animation(name="lift")
    turns = np.arange(9) * 90.0  # two turns, a key each quarter: slerp the shorter way between them
    channel(run, pivot["rotor"], "rotation", turns / 360.0, _quat([1, 0, 0], turns), "VEC4", "LINEAR")
    pulse = [[0, 0, 0], [1, 1, 1], [0, 0, 0], [0, 0, 0], [1.4, 1.4, 1.4], [0, 0, 0], [0, 0, 0], [1, 1, 1], [0, 0, 0]]
    channel(run, pivot["gauge_pivot"], "scale", [0.0, 1.0, 2.0], pulse, "VEC3", "CUBICSPLINE")  # in, value, out
    channel(run, pivot["bolt_ring"], "rotation", [0.0, 0.5, 1.0, 1.5], _quat([0, 1, 0], [0, 45, 90, 135]), "VEC4",
            "STEP")
    channel(lift, pivot["pipe_run"], "translation", [0.0, 1.0, 2.0], [[0, 0, 0], [0, 0.12, 0], [0, 0, 0]], "VEC3",
            "LINEAR")
    doc.animations = [run, lift]
    doc.buffers[0].byteLength = len(blob)
    doc.set_binary_blob(bytes(blob))
    doc.save_binary(str(out))
    return out


if __name__ == "__main__":
    path = main()
    print(f"wrote {path} ({path.stat().st_size} bytes)")
    moving = animate(path, HERE / "pump-running.glb")
    print(f"wrote {moving} ({moving.stat().st_size} bytes)")
