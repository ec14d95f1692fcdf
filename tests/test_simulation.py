"""A simulation's mesh through meshio: volume cells shown as their boundary, wound outwards,
surface cells fanned, fields picked and coloured by a matplotlib map, bad input in one line."""

from pathlib import Path

import meshio
import numpy as np
import pytest

from multigpu.errors import InputError
from multigpu.scene.files import load_model
from multigpu.scene.models import SceneSpec, load_scene, read_range
from multigpu.scene.simulation import Coloring, colours, field, load, lookup, read, surface


def hex_block(n: int = 2):
    """An n x n x n block of unit hexahedra (VTK's corner order), with a point and a cell field."""
    g = np.arange(n + 1, dtype=np.float64)
    z, y, x = np.meshgrid(g, g, g, indexing="ij")
    points = np.c_[x.ravel(), y.ravel(), z.ravel()]
    at = lambda i, j, k: (k * (n + 1) + j) * (n + 1) + i  # noqa: E731
    cells = [[at(i, j, k), at(i + 1, j, k), at(i + 1, j + 1, k), at(i, j + 1, k),
              at(i, j, k + 1), at(i + 1, j, k + 1), at(i + 1, j + 1, k + 1), at(i, j + 1, k + 1)]
             for k in range(n) for j in range(n) for i in range(n)]
    velocity = np.c_[points[:, 0], 2 * points[:, 1], np.zeros(len(points))]
    return meshio.Mesh(points, [("hexahedron", np.array(cells))],
                       point_data={"height": points[:, 2].copy(), "velocity": velocity},
                       cell_data={"pressure": [np.arange(len(cells), dtype=np.float64)]})


def tet_cube():
    """A unit cube cut into five tetrahedra."""
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    tets = np.array([[0, 1, 3, 4], [1, 2, 3, 6], [1, 4, 5, 6], [3, 4, 6, 7], [1, 3, 4, 6]])
    return p, tets


def write(tmp_path: Path, mesh, name: str = "block.vtu") -> Path:
    out = tmp_path / name
    meshio.write(out, mesh)
    return out


def outward(points, faces) -> bool:
    """Every triangle of a convex body faces away from its centre."""
    p = points[faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return bool((np.einsum("ij,ij->i", normal, p.mean(axis=1) - points.mean(axis=0)) > 0).all())


def test_a_block_of_hexahedra_is_its_boundary_wound_outwards():
    mesh = hex_block(2)
    faces, owner, warnings = surface(mesh, Path("block.vtu"))
    assert len(faces) == 6 * 4 * 2 and not warnings  # six sides of four quads, two triangles each
    assert outward(np.asarray(mesh.points), faces)
    keys = {tuple(sorted(f)) for f in faces.tolist()}
    assert len(keys) == len(faces)  # no face twice
    # each triangle's cell holds all three of its corners
    cells = mesh.cells[0].data
    assert all(set(f) <= set(cells[o]) for f, o in zip(faces.tolist(), owner.tolist()))


def test_tetrahedra_and_the_triangles_on_their_boundary_are_drawn_once():
    p, tets = tet_cube()
    bottom = np.array([[0, 1, 3], [1, 2, 3]])  # lies on the tets' boundary: not drawn again
    mesh = meshio.Mesh(p, [("tetra", tets), ("triangle", bottom), ("line", np.array([[0, 6]]))])
    faces, owner, warnings = surface(mesh, Path("cube.vtu"))
    assert len(faces) == 12 and outward(p, faces)
    assert (owner < len(tets)).all()  # the bottom's triangles are the tets' faces, not the surface cells
    assert warnings == ["1 line and vertex cells not drawn"]


def test_quads_and_polygons_are_fanned_and_unknown_kinds_named():
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0.5, 0]], float)
    mesh = meshio.Mesh(p, [("quad", np.array([[0, 1, 2, 3]])), ("polygon", np.array([[1, 4, 2, 0, 3]]))])
    faces, owner, _ = surface(mesh, Path("flat.vtu"))
    assert faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 2], [1, 2, 0], [1, 0, 3]]
    assert owner.tolist() == [0, 0, 1, 1, 1]
    with pytest.raises(InputError, match=r"flat.vtu: no cells to draw as a surface \(cell kinds: line\)"):
        surface(meshio.Mesh(p, [("line", np.array([[0, 1]]))]), Path("flat.vtu"))


def test_fields_by_name_component_and_magnitude():
    mesh = hex_block(1)
    values, where, label = field(mesh, "velocity", Path("b.vtu"))
    assert where == "point" and label == "velocity (magnitude)"
    assert np.allclose(values, np.hypot(mesh.points[:, 0], 2 * mesh.points[:, 1]))
    assert np.array_equal(field(mesh, "velocity:y", Path("b.vtu"))[0], 2 * mesh.points[:, 1])
    assert np.array_equal(field(mesh, "velocity:0", Path("b.vtu"))[0], mesh.points[:, 0])
    assert field(mesh, "pressure", Path("b.vtu"))[1:] == ("cell", "pressure")
    with pytest.raises(InputError, match=r"b.vtu: no field 'speed' \(the fields: height, velocity, pressure\)"):
        field(mesh, "speed", Path("b.vtu"))
    with pytest.raises(InputError, match=r"field 'velocity' has 3 components: no component 'w'"):
        field(mesh, "velocity:w", Path("b.vtu"))


def test_colours_come_from_the_map_at_the_range_and_nan_is_grey():
    table = lookup("viridis")
    assert table.shape == (256, 4) and table.dtype == np.uint8
    got = colours(np.array([0.0, 10.0, 5.0, -3.0, 99.0, np.nan]), table, 0.0, 10.0)
    assert np.array_equal(got[:5], table[[0, 255, 128, 0, 255]])
    assert got[5].tolist() == [128, 128, 128, 255]
    with pytest.raises(InputError, match="unknown colour map 'nope'"):
        lookup("nope")


def test_a_point_field_colours_vertices_and_a_cell_field_colours_faces(tmp_path):
    path = write(tmp_path, hex_block(2))
    mesh, meta = load(path, "height", "plasma", None)
    table = lookup("plasma")
    z = np.asarray(mesh.vertices)[:, 2]
    assert np.array_equal(np.asarray(mesh.visual.vertex_colors), table[np.floor(z / 2 * 255 + 0.5).astype(int)])
    assert meta["color_by"] == {"field": "height", "where": "point", "range": [0.0, 2.0], "colormap": "plasma"}
    flat, meta = load(path, "pressure", "viridis", (0.0, 14.0))
    rgba = np.asarray(flat.visual.vertex_colors).reshape(-1, 3, 4)
    assert (rgba == rgba[:, :1]).all()  # one colour a triangle
    assert meta["color_by"]["range"] == [0.0, 14.0] and len(flat.vertices) == 3 * len(flat.faces)
    names = [(f["name"], f["where"], f["components"]) for f in meta["fields"]]
    assert names == [("height", "point", 1), ("velocity", "point", 3), ("pressure", "cell", 1)]


def test_a_vtu_loads_as_a_scene_with_its_colours_and_the_colouring_keys_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MULTIGPU_CACHE", str(tmp_path / "cache"))
    path = write(tmp_path, hex_block(3))
    a, _ = load_scene(SceneSpec(model=str(path), color_by="height"))
    assert a.vertex_colors is not None and a.n_triangles == 6 * 9 * 2
    assert a.meta["simulation"]["color_by"]["field"] == "height"
    b, info = load_scene(SceneSpec(model=str(path), color_by="velocity", colormap="turbo"))
    assert not info["cached"] and not np.array_equal(a.vertex_colors, b.vertex_colors)
    _, info = load_scene(SceneSpec(model=str(path), color_by="height"))
    assert info["cached"]


def test_non_finite_points_drop_their_faces_with_a_warning(tmp_path):
    mesh = hex_block(2)
    mesh.points[0] = np.nan  # a corner: three boundary quads use it
    faces, _, _ = surface(mesh, Path("block.vtu"))
    scene = load_model(write(tmp_path, mesh), coloring=Coloring("height"))
    assert scene.n_triangles == 48 - (faces == 0).any(axis=1).sum() < 48
    assert any("non-finite" in w for w in scene.meta["warnings"])


def test_an_unreadable_file_is_one_line(tmp_path):
    bad = tmp_path / "broken.vtu"
    bad.write_text("<VTKFile type='UnstructuredGrid'><Unstru")
    with pytest.raises(InputError, match=r"broken.vtu: cannot read as VTU \(meshio: "):
        read(bad)
    for text in ("5,1", "1,inf", "1;2", "x,2"):
        with pytest.raises(InputError, match="must be "):
            read_range(text)
    assert read_range("-1.5,2e3") == (-1.5, 2000.0)


def test_the_colour_bar_shows_the_map_from_end_to_end_in_a_corner():
    from multigpu.display.colorbar import MARGIN, STRIP, color_bar, legend_of, stamp

    legend = {"field": "velocity (magnitude)", "where": "point", "range": [0.0, 13.4], "colormap": "plasma"}
    assert legend_of({"simulation": {"color_by": legend}}) == legend and legend_of({}) is None
    table = lookup("plasma")
    bar = color_bar(legend, table)
    row = bar[MARGIN + 12 + STRIP // 2, MARGIN:bar.shape[1] - MARGIN]
    assert np.array_equal(row[0], table[0, :3]) and np.array_equal(row[-1], table[-1, :3])
    img = np.zeros((40, 500, 3), dtype=np.uint8)
    out = stamp(img, bar)  # a picture lower than the bar: its bottom rows
    assert np.array_equal(out[:, :bar.shape[1]], bar[-40:]) and not out[:, bar.shape[1]:].any() and not img.any()


def test_each_tile_stamps_its_part_of_the_colour_bar_and_the_wall_shows_it_whole():
    from multigpu.core.canvas import Canvas
    from multigpu.display.colorbar import MARGIN, TileKey, color_bar
    from multigpu.records.mosaic import stitch

    legend = {"field": "p", "where": "cell", "range": [1.0, 2.0], "colormap": "viridis"}
    bar = color_bar(legend, lookup("viridis"))
    canvas = Canvas((2, 2), (100, 40), (0, 0))  # the bar spans all four tiles
    tiles = np.zeros((4, 40, 100, 3), np.uint8)
    for k, rect in enumerate(canvas.tiles()):
        TileKey(bar, rect).stamp(tiles[k])
    img = stitch(tiles, canvas.tiles(), canvas.size)
    H = img.shape[0]
    h, w = min(bar.shape[0], H - MARGIN), bar.shape[1]
    assert np.array_equal(img[H - MARGIN - h:H - MARGIN, MARGIN:MARGIN + w], bar[bar.shape[0] - h:])
    assert not img[:, MARGIN + w:].any() and not img[H - MARGIN:].any()
    assert TileKey.of({}, (0, 0, 10, 10)) is None
