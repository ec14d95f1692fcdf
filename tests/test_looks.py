"""Users' models as they look (scene/looks.py): colours and normals from the file, crease-angle
normals where it has none, one neutral grey where it has no colour, and the per-object palette
as a view. In one process: model files written with trimesh into tmp_path, rendered headless."""

import numpy as np
import pytest
import trimesh
from trimesh.visual import ColorVisuals, TextureVisuals
from trimesh.visual.material import PBRMaterial, SimpleMaterial

from multigpu.scene import looks
from multigpu.scene.models import load_model

RED, BLUE, ORANGE = [200, 40, 30, 255], [30, 60, 220, 255], [230, 140, 20, 255]


def boxes_glb(path, with_ball=True, textured=False):
    """Two boxes of two glTF materials, (``with_ball``) a sphere with COLOR_0 vertex colours and
    (``textured``) a textured sphere (a mipmapped checker repeated over its UVs)."""
    s = trimesh.Scene()
    for name, col, pos in (("red", RED, [0, 0, 0]), ("blue", BLUE, [2, 0, 0])):
        b = trimesh.creation.box([1, 1, 1])
        b.apply_translation(pos)
        b.visual = TextureVisuals(material=PBRMaterial(baseColorFactor=col))
        s.add_geometry(b, node_name=name, geom_name=name)
    if with_ball:
        c = trimesh.creation.icosphere(2, radius=0.6)
        c.apply_translation([1, 2, 0])
        rgb = ((c.vertices - c.vertices.min(0)) / np.ptp(c.vertices, 0) * 255).astype(np.uint8)
        c.visual = ColorVisuals(c, vertex_colors=np.column_stack([rgb, np.full(len(rgb), 255, np.uint8)]))
        s.add_geometry(c, node_name="ball", geom_name="ball")
    if textured:
        from PIL import Image

        t = trimesh.creation.uv_sphere(0.7, count=[24, 24])
        t.apply_translation([1.0, 0.8, -1.4])
        image = Image.fromarray((np.indices((16, 16)).sum(0) % 2 * 200 + 40).astype(np.uint8)).convert("RGB")
        uv = np.column_stack([np.arctan2(t.vertices[:, 1] - 0.8, t.vertices[:, 2] + 1.4), t.vertices[:, 0]]) * 0.25
        t.visual = TextureVisuals(uv=uv, material=PBRMaterial(baseColorTexture=image, baseColorFactor=ORANGE))
        s.add_geometry(t, node_name="textured", geom_name="textured")
    path.write_bytes(s.export(file_type="glb"))
    return path


def test_gltf_materials_are_each_objects_colour(tmp_path):
    scene = load_model(boxes_glb(tmp_path / "m.glb", with_ball=False))
    got = sorted(tuple(np.rint(c * 255).astype(int)) for c in scene.colors)
    assert got == sorted([tuple(RED[:3]), tuple(BLUE[:3])])
    assert scene.vertex_colors is None  # one colour per part: nothing per vertex
    assert scene.meta["look"]["colors"] == "material" and scene.meta["look"]["materials"] == 2


def test_gltf_vertex_colours_are_kept_per_vertex_where_an_object_varies(tmp_path):
    scene = load_model(boxes_glb(tmp_path / "m.glb"))
    assert scene.vertex_colors is not None and scene.vertex_colors.shape == (len(scene.vertices), 4)
    assert len({tuple(c) for c in scene.vertex_colors[:, :3]}) > 10  # the ball's gradient
    assert {tuple(RED[:3]), tuple(BLUE[:3])} <= {tuple(c) for c in scene.vertex_colors[:, :3]}


def test_obj_usemtl_kd_colours_its_parts(tmp_path):
    s = trimesh.Scene()
    for name, col, pos in (("r", RED, [0, 0, 0]), ("b", BLUE, [2, 0, 0])):
        b = trimesh.creation.box()
        b.apply_translation(pos)
        b.visual = TextureVisuals(material=SimpleMaterial(diffuse=col))
        s.add_geometry(b, node_name=name, geom_name=name)
    s.export(str(tmp_path / "m.obj"))
    scene = load_model(tmp_path / "m.obj")
    assert sorted(tuple(np.rint(c * 255).astype(int)) for c in scene.colors) == sorted([tuple(RED[:3]),
                                                                                         tuple(BLUE[:3])])


def test_ply_vertex_colours_survive(tmp_path):
    m = trimesh.creation.icosphere(2)
    rgba = np.random.default_rng(0).integers(0, 256, (len(m.vertices), 4)).astype(np.uint8)
    m.visual = ColorVisuals(m, vertex_colors=rgba)
    m.export(str(tmp_path / "v.ply"))
    scene = load_model(tmp_path / "v.ply")
    got = {tuple(np.round(p, 4)): tuple(c) for p, c in zip(scene.world_positions(), scene.vertex_colors)}
    want = {tuple(np.round(p, 4)): tuple(c) for p, c in zip(m.vertices, rgba)}
    assert got == want  # every vertex keeps its own colour (the sphere is smooth: none split)


def test_a_model_without_colours_is_one_neutral_grey(tmp_path):
    trimesh.creation.box().export(str(tmp_path / "b.stl"))
    scene = load_model(tmp_path / "b.stl")
    assert np.allclose(scene.colors, looks.NEUTRAL) and scene.vertex_colors is None
    assert scene.meta["look"]["colors"] == "none"


def test_a_box_keeps_flat_faces_and_a_sphere_stays_smooth():
    box = trimesh.creation.box()
    source, normals, faces = looks.crease_normals(np.asarray(box.vertices), np.asarray(box.faces))
    assert len(source) == 24  # 8 corners, 3 faces each
    assert np.allclose(np.abs(normals).max(axis=1), 1.0)  # every normal along an axis: flat faces
    tri = box.vertices[source][faces]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    face_n /= np.linalg.norm(face_n, axis=1, keepdims=True)
    assert np.allclose(normals[faces], face_n[:, None, :])  # each corner's normal is its face's
    ball = trimesh.creation.icosphere(3)
    source, normals, _ = looks.crease_normals(np.asarray(ball.vertices), np.asarray(ball.faces))
    assert len(source) == len(ball.vertices)  # no split
    radial = ball.vertices[source] / np.linalg.norm(ball.vertices[source], axis=1, keepdims=True)
    assert (normals * radial).sum(axis=1).min() > 0.99


def test_unshared_stl_vertices_are_joined_by_position():
    """STL keeps three vertices per triangle: faces still share edges by position, so a sphere in
    STL is smooth, not faceted."""
    ball = trimesh.creation.icosphere(2)
    verts = ball.vertices[ball.faces].reshape(-1, 3)
    faces = np.arange(len(verts)).reshape(-1, 3)
    source, normals, _ = looks.crease_normals(verts, faces)
    radial = verts[source] / np.linalg.norm(verts[source], axis=1, keepdims=True)
    assert (normals * radial).sum(axis=1).min() > 0.98


def test_faces_of_different_meshes_are_not_smoothed_together():
    """Two halves of a flat sheet folded at 20 degrees: smooth across as one mesh, split as two."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [-1, 0, 0.36], [-1, 1, 0.36]], dtype=float)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 0, 2], [4, 2, 5]])
    one, _, _ = looks.crease_normals(v, f)
    two, _, _ = looks.crease_normals(v, f, groups=np.array([0, 0, 1, 1]))
    assert len(one) == 6 and len(two) == 8  # the shared edge's two vertices split


def test_normals_from_the_file_are_used(tmp_path):
    m = trimesh.creation.icosphere(1)
    bent = m.vertex_normals + [0.3, 0, 0]  # not what any computation would give
    m.vertex_normals = bent / np.linalg.norm(bent, axis=1, keepdims=True)
    m.export(str(tmp_path / "n.ply"), include_attributes=True)
    loaded = trimesh.load(str(tmp_path / "n.ply"), process=False)
    if looks.mesh_normals(loaded) is None:
        pytest.skip("this trimesh writes no PLY normals")
    scene = load_model(tmp_path / "n.ply")
    assert scene.meta["look"]["normals"] == "from the file"
    got = {tuple(np.round(p, 4)): n for p, n in zip(scene.world_positions(), scene.vertices[:, 3:6])}
    for p, n in zip(m.vertices, m.vertex_normals):
        assert np.allclose(got[tuple(np.round(p, 4))], n, atol=1e-5)


def test_split_colors_keeps_one_colour_per_uniform_object():
    rgba = np.array([[255, 0, 0, 255]] * 3 + [[0, 0, 255, 255]] * 3, dtype=np.uint8)
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    colors, per_vertex = looks.split_colors(rgba, faces, np.array([0, 1]), 2)
    assert per_vertex is None and np.allclose(colors, [[1, 0, 0], [0, 0, 1]])
    colors, per_vertex = looks.split_colors(rgba, faces, np.array([0, 0]), 1)
    assert per_vertex is rgba and np.allclose(colors, [[0.5, 0, 0.5]])


def test_the_model_is_drawn_in_its_colours_and_the_palette_is_a_view(tmp_path, ctx):
    from multigpu.core.camera import look_at, perspective
    from multigpu.gpu.render import RegionRenderer
    from multigpu.scene.models import SceneSpec, load_scene

    scene, _ = load_scene(SceneSpec(model=str(boxes_glb(tmp_path / "m.glb")), cluster=0), use_cache=False)
    view = look_at([1.0, 1.0, 6.0], [1.0, 1.0, 0.0], [0, 1, 0])
    proj = perspective(50, 1.0, 0.1, 100)
    size = (96, 96)
    every = np.ones(scene.n_objects, dtype=bool)
    images = {}
    for view_name in ("model", "objects"):
        r = RegionRenderer(ctx, scene, size, "scissor", colors=view_name)
        images[view_name] = r.render(view, proj, np.array([0.0, 0.0, 1.0]), (0, 0, *size), every)
        r.release()
    img = images["model"].astype(int)
    red = (img[..., 0] > 100) & (img[..., 0] > 3 * img[..., 2])
    blue = (img[..., 2] > 100) & (img[..., 2] > 3 * img[..., 0])
    assert red.sum() > 100 and blue.sum() > 100, (red.sum(), blue.sum())
    assert np.nonzero(red)[1].mean() < np.nonzero(blue)[1].mean()  # red on the left, blue on the right
    assert (images["model"] != images["objects"]).any()


def test_levels_of_detail_keep_a_colour_border():
    """A flat grid, red left and blue right, simplified to 8 triangles: without its colours the
    simplifier spans the border with big triangles (the whole plane mixed); weighing them keeps
    the border, so only a thin strip along it mixes the two."""
    from multigpu.scene.lod import simplify

    n = 40
    xs, ys = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    pos = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(n * n)]).astype(np.float32)
    a = (np.arange(n - 1)[None, :] + n * np.arange(n - 1)[:, None]).ravel()
    idx = np.column_stack([a, a + 1, a + n + 1, a, a + n + 1, a + n]).astype(np.uint32).ravel()
    col = np.where(pos[:, :1] > 0.5, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]).astype(np.float32)

    def mixed_area(colors):
        tri = simplify(pos, idx, 8, False, colors)[0].reshape(-1, 3)
        mixed = np.ptp(col[tri][:, :, 2], axis=1) > 0
        p = pos[tri]
        return (np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)[mixed] / 2).sum()

    assert mixed_area(None) > 0.5
    assert mixed_area(col) < 0.1


def test_gltf_alpha_mask_leaves_out_what_its_cutoff_hides_and_blend_is_drawn_opaque(tmp_path):
    s = trimesh.Scene()
    for name, col, mode, pos in (("shown", [200, 40, 30, 200], "MASK", 0), ("hidden", [30, 60, 220, 60], "MASK", 2),
                                 ("glass", [30, 200, 60, 80], "BLEND", 4)):
        b = trimesh.creation.box()
        b.apply_translation([pos, 0, 0])
        b.visual = TextureVisuals(material=PBRMaterial(baseColorFactor=col, alphaMode=mode, alphaCutoff=0.5))
        s.add_geometry(b, node_name=name, geom_name=name)
    (tmp_path / "a.glb").write_bytes(s.export(file_type="glb"))
    scene = load_model(tmp_path / "a.glb")
    assert scene.n_triangles == 24  # the box at alpha 60/255 < 0.5 is left out; the BLEND one stays
    a = scene.meta["look"]["alpha"]
    assert a == {"blend_drawn_opaque": 1, "mask": 2, "masked_faces": 12}
    assert any("alpha cutoff" in w for w in scene.meta["warnings"])
    assert scene.bmax.max(axis=0)[0] > 4  # the glass box is there
