"""The buffers file: a scene's GL buffers written once beside its cache, mapped by every rank
of a host, and drawn from directly where the driver can (GL_AMD_pinned_memory)."""

import os

import numpy as np
import pytest

from multigpu.core.drawlist import DrawList
from multigpu.gpu import buffers
from multigpu.gpu.buffers import buffers_path, ensure_buffers, map_buffers, pack_vertices, write_buffers
from multigpu.scene.models import SceneSpec, load_scene


@pytest.fixture(scope="module")
def cached(tmp_path_factory):
    """A plant of ~20 k triangles loaded from (and mapped out of) a fresh cache."""
    cache = tmp_path_factory.mktemp("cache")
    old = os.environ.get("MULTIGPU_CACHE")
    os.environ["MULTIGPU_CACHE"] = str(cache)
    try:
        load_scene(SceneSpec(triangles=20_000, ranks=4))
        scene, info = load_scene(SceneSpec(triangles=20_000, ranks=4))
    finally:
        if old is None:
            del os.environ["MULTIGPU_CACHE"]
        else:
            os.environ["MULTIGPU_CACHE"] = old
    assert info["cached"]
    return scene, info["cache"]


def test_the_file_holds_the_buffers_the_renderer_would_upload(cached):
    scene, cache = cached
    path = ensure_buffers(cache, scene)
    assert path == buffers_path(cache) and path.is_file()
    draws = DrawList(scene)
    maps = map_buffers(path, scene, draws)
    np.testing.assert_array_equal(maps["vertices"], pack_vertices(scene.vertices))
    np.testing.assert_array_equal(maps["indices"], draws.indices)
    np.testing.assert_array_equal(maps["objects"], draws.vertex_object)
    for m in maps.values():
        assert m.ctypes.data % buffers.PAGE == 0  # each array starts on a page (pinned memory wants it)


def test_a_whole_file_is_written_once_and_a_wrong_one_is_never_used(cached, tmp_path):
    scene, cache = cached
    path = ensure_buffers(cache, scene)
    stamp = path.stat().st_mtime_ns
    assert ensure_buffers(cache, scene) == path and path.stat().st_mtime_ns == stamp  # reused, not rewritten
    draws = DrawList(scene)
    other = tmp_path / "x.gl"
    write_buffers(other, scene, draws)
    assert map_buffers(other, scene, draws) is not None
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name]  # no temporary left behind
    moved = scene.translated((1e3, -7.0, 0.5))
    moved.centers = moved.centers[::-1].copy()  # another draw order: the index layout differs
    assert map_buffers(other, moved, DrawList(moved)) is None
    with open(other, "r+b") as fh:  # cut short, as a crash mid-write without the rename would leave it
        fh.truncate(other.stat().st_size - buffers.PAGE)
    assert map_buffers(other, scene, draws) is None
    other.write_bytes(b"not a buffers file")
    assert map_buffers(other, scene, draws) is None
    assert map_buffers(tmp_path / "missing", scene, draws) is None
    assert ensure_buffers(None, scene) is None  # no cache: the renderer uploads from the scene


def test_every_rank_uploads_its_own_copy_when_asked(cached, monkeypatch):
    from multigpu.errors import InputError

    scene, cache = cached
    monkeypatch.setenv("MULTIGPU_GL_BUFFERS", "upload")
    assert ensure_buffers(cache, scene) is None
    monkeypatch.setenv("MULTIGPU_GL_BUFFERS", "pinned")
    with pytest.raises(InputError, match="MULTIGPU_GL_BUFFERS must be 'shared' or 'upload', got 'pinned'"):
        ensure_buffers(cache, scene)


def test_a_cache_that_cannot_be_written_gives_no_file(cached, tmp_path):
    scene, _ = cached
    (tmp_path / "a-file").write_text("")  # the cache "directory" is a file: nothing can be written there
    assert ensure_buffers(tmp_path / "a-file" / "scene.npz", scene) is None


def _frames(renderer, scene, n=3):
    from multigpu.core.camera import frame_matrices
    from multigpu.scene.paths import generate

    path = generate("walkthrough", scene, 12)
    out = []
    for f in range(0, 12, 12 // n):
        view, proj, _ = frame_matrices(path.camera(f), renderer.size)
        mask = np.arange(scene.n_objects) % (f + 2) != 0  # a subset, as a rank's region draws
        out.append(renderer.render(view, proj, np.array([0.3, -0.5, 0.81]), (0, 0, *renderer.size), mask))
    return np.stack(out)


def test_drawing_from_the_shared_file_gives_the_uploaded_pixels(cached, monkeypatch):
    from multigpu.gpu.render import EglUnavailable, RegionRenderer, create_context

    scene, cache = cached
    try:
        ctx, _ = create_context()
    except EglUnavailable as exc:
        pytest.skip(str(exc))
    path = ensure_buffers(cache, scene)
    ref = RegionRenderer(ctx, scene, (96, 64), "scissor")
    assert ref.storage == "uploaded"
    want = _frames(ref, scene)
    ref.release()
    assert want.std() > 5  # the frames show the plant, not a blank
    if buffers.can_pin(ctx) is None:
        r = RegionRenderer(ctx, scene, (96, 64), "scissor", path)
        assert r.storage == f"shared: {path}"
        with open("/proc/self/maps") as fh:
            assert str(path) in fh.read()  # the GL buffers are the file's pages
        np.testing.assert_array_equal(_frames(r, scene), want)
        r.release()
    monkeypatch.setattr(buffers, "can_pin", lambda ctx: "no pinning here")  # e.g. NVIDIA's GL
    from multigpu.gpu import render

    monkeypatch.setattr(render, "can_pin", buffers.can_pin)
    r = RegionRenderer(ctx, scene, (96, 64), "scissor", path)
    assert r.storage.startswith("uploaded from") and "no pinning here" in r.storage
    np.testing.assert_array_equal(_frames(r, scene), want)
    r.release()
    ctx.release()
