"""A model's colour textures (scene/textures.py): glTF baseColorTexture with its sampler's wrap and
filter, OBJ map_Kd, missing and oversized images, the scene cache and buffers file, and the
pixels drawn. In one process: model files written with trimesh into tmp_path, rendered headless."""

import json
import struct

import numpy as np
import pytest
import trimesh
from PIL import Image
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

from multigpu.scene import textures
from multigpu.scene.models import load_model

CHECKER = (np.indices((8, 8)).sum(0) % 2 * 255).astype(np.uint8)


def checker(colour=(255, 255, 255)) -> Image.Image:
    """An 8x8 checker of black and ``colour``."""
    return Image.fromarray((CHECKER[..., None] // 255 * np.array(colour, dtype=np.uint8)).astype(np.uint8), "RGB")


def quad(uv_scale=1.0, image=None, factor=None, mode="OPAQUE", at=(0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    """A unit square facing +z with UVs over [0, uv_scale], textured with ``image``."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float) + at
    m = trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float) * uv_scale
    m.visual = TextureVisuals(uv=uv, material=PBRMaterial(baseColorTexture=image or checker(), baseColorFactor=factor,
                                                          alphaMode=mode, alphaCutoff=0.5))
    return m


def glb(path, meshes: dict, sampler: dict | None = None):
    """``meshes`` (name -> mesh) as a GLB at ``path``; ``sampler`` (glTF sampler keys) given to
    every texture (trimesh writes none)."""
    s = trimesh.Scene()
    for name, m in meshes.items():
        s.add_geometry(m, node_name=name, geom_name=name)
    data = s.export(file_type="glb")
    if sampler is not None:
        n = struct.unpack("<I", data[12:16])[0]
        doc = json.loads(data[20:20 + n])
        doc["samplers"] = [sampler]
        for t in doc["textures"]:
            t["sampler"] = 0
        text = json.dumps(doc).encode()
        text += b" " * (-len(text) % 4)
        rest = data[20 + n:]
        data = (data[:8] + struct.pack("<I", 20 + len(text) + len(rest)) + struct.pack("<I", len(text)) + b"JSON"
                + text + rest)
    path.write_bytes(data)
    return path


def test_a_gltf_texture_is_loaded_with_its_uvs_and_sampler(tmp_path):
    path = glb(tmp_path / "t.glb", {"q": quad(2.0)}, {"wrapS": 33071, "wrapT": 33648, "magFilter": 9728})
    scene = load_model(path)
    assert scene.meta["look"]["textures"]["count"] == 1
    top = textures.layer_image(scene.texels, scene.texture_levels, 0)
    assert top.shape == (8, 8, 4) and (top[..., 0] == CHECKER).all()  # row 0 is the image's top row
    assert textures.layer_image(scene.texels, scene.texture_levels, 0, 3).shape == (1, 1, 4)  # mip levels to 1x1
    assert scene.texture_modes.tolist() == [[1.0, 2.0, 1.0, 0.0]]  # clamp, mirror, nearest, opaque
    uv = scene.texcoords
    assert uv.shape == (scene.vertices.shape[0], 3) and (uv[:, 2] == 0).all()
    assert sorted(set(uv[:, 0].tolist())) == [0.0, 2.0]
    assert sorted(set(uv[:, 1].tolist())) == [-1.0, 1.0]  # v runs down the image: 1 - v as trimesh gives it
    assert scene.meta["look"]["textures"]["count"] == 1
    assert not scene.meta["warnings"]


def test_parts_share_a_layer_per_image_and_untextured_parts_have_none(tmp_path):
    red = checker((255, 0, 0))
    path = glb(tmp_path / "t.glb", {"a": quad(image=red), "b": quad(image=red.copy(), at=(2, 0, 0)),
                                    "c": quad(image=checker((0, 0, 255)), at=(4, 0, 0)),
                                    "d": trimesh.creation.box()})
    scene = load_model(path)
    assert scene.meta["look"]["textures"]["count"] == 2  # one layer per distinct image
    layers = scene.texcoords[:, 2]
    assert set(np.unique(layers).tolist()) == {-1.0, 0.0, 1.0}


def test_obj_map_kd_is_drawn_and_a_missing_image_is_named(tmp_path):
    checker((0, 255, 0)).save(tmp_path / "wood.png")
    (tmp_path / "m.mtl").write_text("newmtl wood\nKd 1 1 1\nmap_Kd wood.png\nnewmtl gone\nKd 0.5 0.1 0.1\n"
                                    "map_Kd missing.png\n")
    (tmp_path / "m.obj").write_text("mtllib m.mtl\no a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\n"
                                    "vt 1 1\nvt 0 1\nusemtl wood\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\no b\nv 0 0 1\n"
                                    "v 1 0 1\nv 1 1 1\nusemtl gone\nf 5/1 6/2 7/3\n")
    scene = load_model(tmp_path / "m.obj")
    assert scene.meta["look"]["textures"]["count"] == 1
    assert textures.layer_image(scene.texels, scene.texture_levels, 0)[..., 1].max() == 255
    assert [w for w in scene.meta["warnings"] if "missing.png" in w and "stands in" in w]
    assert (128, 26, 26) in {tuple(np.rint(c * 255).astype(int)) for c in scene.colors}  # its Kd stands in


def test_an_oversized_texture_is_downscaled_with_a_warning():
    layers = textures.Layers()
    layers.layer(Image.new("RGB", (textures.MAX_SIDE + 8, 4), (9, 9, 9)), None)
    warnings = []
    texels, levels, modes = layers.pack(warnings)
    assert max(textures.layer_image(texels, levels, 0).shape[:2]) == textures.MAX_SIDE and "downscaled" in warnings[0]


def test_textures_survive_the_scene_cache_and_levels_of_detail(tmp_path, monkeypatch):
    from multigpu.scene.models import SceneSpec, load_scene

    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path / "cache"))
    sphere = trimesh.creation.uv_sphere(1.0, count=[64, 64])
    sphere.visual = TextureVisuals(uv=sphere.vertices[:, :2] * 0.5 + 0.5,
                                   material=PBRMaterial(baseColorTexture=checker()))
    path = glb(tmp_path / "s.glb", {"s": sphere})
    built, info = load_scene(SceneSpec(model=str(path), cluster=0, ranks=1))
    again, info2 = load_scene(SceneSpec(model=str(path), cluster=0, ranks=1))
    assert not info["cached"] and info2["cached"]
    assert (np.asarray(again.texels) == built.texels).all()
    assert (np.asarray(again.texcoords) == built.texcoords).all()
    assert isinstance(again.texels, np.memmap)  # mapped: one copy per host
    assert again.lod_count[0, 1] > 0  # simplified with its UVs weighed


@pytest.fixture(params=["pool", "array"])
def texture_path(request, monkeypatch):
    """Each drawing test on both texture paths (``MULTIGPU_TEXTURES``)."""
    monkeypatch.setenv("MULTIGPU_TEXTURES", request.param)
    return request.param


def draw(ctx, path, shared=False, tmp_path=None, colors="model", size=(64, 64)):
    from multigpu.core.camera import look_at, perspective
    from multigpu.gpu.buffers import ensure_buffers
    from multigpu.gpu.render import RegionRenderer
    from multigpu.scene.models import SceneSpec, load_scene

    scene, info = load_scene(SceneSpec(model=str(path), cluster=0, ranks=1), use_cache=shared)
    buffers = ensure_buffers(info["cache"], scene) if shared else None
    r = RegionRenderer(ctx, scene, size, "scissor", shared=buffers, colors=colors)
    view = look_at([0.5, 0.5, 1.2], [0.5, 0.5, 0.0], [0, 1, 0])
    img = r.render(view, perspective(60, 1.0, 0.1, 10), np.array([0.0, 0.0, 1.0]), (0, 0, *size),
                   np.ones(scene.n_objects, dtype=bool))
    storage = r.storage
    r.release()
    return img, storage


def test_the_texture_is_drawn_and_multiplies_the_material_colour(tmp_path, ctx, texture_path):
    img, _ = draw(ctx, glb(tmp_path / "t.glb", {"q": quad()}, {"magFilter": 9728}))
    centre = img[16:48, 16:48].reshape(-1, 3).astype(int)
    dark, light = (centre.sum(1) < 60).mean(), (centre.sum(1) > 400).mean()
    assert dark > 0.3 and light > 0.3, (dark, light)  # the checker, not one flat colour
    tinted, _ = draw(ctx, glb(tmp_path / "f.glb", {"q": quad(factor=[255, 0, 0, 255])}))
    assert tinted[16:48, 16:48, 1:].max() < 10 and tinted[16:48, 16:48, 0].max() > 150  # white x red = red
    palette, _ = draw(ctx, tmp_path / "t.glb", colors="objects")
    assert len({tuple(p) for p in palette[16:48, 16:48].reshape(-1, 3)}) < 8  # the view leaves textures out


@pytest.mark.parametrize("wrap", [10497, 33071, 33648])
def test_each_wrap_mode_draws_as_specified(tmp_path, ctx, wrap, texture_path):
    """UVs over [0, 2] on a checker of 8: repeat draws 16 squares a side, mirror repeats it
    reflected, clamp draws 8 squares and then the last texel's column and row."""
    img, _ = draw(ctx, glb(tmp_path / "w.glb", {"q": quad(2.0)}, {"wrapS": wrap, "wrapT": wrap, "magFilter": 9728}))
    from multigpu.gpu.render import BACKGROUND

    row = img[32, :, 0].astype(int)
    on = row[row != round(BACKGROUND[0] * 255)] > 127  # across the quad
    changes = int((np.diff(on.astype(int)) != 0).sum())
    if wrap == 33071:
        assert changes <= 8, changes  # 8 squares, then the clamped last texel
    else:
        assert changes >= 13, changes  # 16 squares (mirror: two alike where it reflects)
    others = {w: draw(ctx, glb(tmp_path / f"o{w}.glb", {"q": quad(2.0)}, {"wrapS": w, "wrapT": w,
                                                                          "magFilter": 9728}))[0]
              for w in (10497, 33071, 33648) if w != wrap}
    assert all((img != o).any() for o in others.values())


def test_a_mask_texture_leaves_out_texels_under_its_cutoff(tmp_path, ctx, texture_path):
    rgba = np.zeros((8, 8, 4), dtype=np.uint8)
    rgba[..., :3] = 255
    rgba[..., 3] = CHECKER  # half the texels transparent
    img, _ = draw(ctx, glb(tmp_path / "m.glb", {"q": quad(image=Image.fromarray(rgba, "RGBA"), mode="MASK")}))
    centre = img[16:48, 16:48].reshape(-1, 3).astype(int)
    from multigpu.gpu.render import BACKGROUND

    background = np.rint(np.array(BACKGROUND) * 255).astype(int)
    assert 0.3 < (np.abs(centre - background).sum(1) <= 3).mean() < 0.7


def test_the_buffers_file_draws_the_same_pixels(tmp_path, ctx, monkeypatch):
    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path / "cache"))
    path = glb(tmp_path / "t.glb", {"q": quad(2.0), "b": trimesh.creation.box()}, {"magFilter": 9729})
    uploaded, _ = draw(ctx, path)
    shared, storage = draw(ctx, path, shared=True)
    assert "uploaded" != storage and (uploaded == shared).all()


def test_the_pools_filtering_matches_the_hardwares(tmp_path, ctx, monkeypatch):
    """A minified, mipmapped, linearly filtered texture (UVs over [0, 6] on a 64x64 image): the
    pool's filtering in the shader draws what the texture array's hardware filtering draws, to
    within rounding (the two blend in different precisions)."""
    rng = np.random.default_rng(3)
    smooth = np.asarray(Image.fromarray(rng.integers(0, 255, (8, 8, 3), dtype=np.uint8)).resize((64, 64)))
    path = glb(tmp_path / "m.glb", {"q": quad(6.0, image=Image.fromarray(smooth))}, {"magFilter": 9729})
    got = {}
    for how in ("pool", "array"):
        monkeypatch.setenv("MULTIGPU_TEXTURES", how)
        got[how] = draw(ctx, path, size=(96, 96))[0].astype(int)
    diff = np.abs(got["pool"] - got["array"])
    assert diff.mean() < 1.5 and np.percentile(diff, 99) <= 8, (diff.mean(), np.percentile(diff, 99))
