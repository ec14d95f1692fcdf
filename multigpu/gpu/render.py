"""Headless GL rendering of one rank's screen region (moderngl on EGL; textures: ``texturing.py``).

One context per rank, the whole scene uploaded once (a series' next step swapped in: ``rescene``).
A frame is ONE ``render_indirect`` call (two where some of a moving scene's objects stand still:
``pose``) over the draw commands of the objects in the rank's T' mask (one command per run of
visible objects in the spatially ordered index buffer, built with numpy: see ``drawlist.py``), into a
full-display-sized framebuffer with the full-display viewport and projection, scissored to the
rank's region (``scissor``, the default where the display fits one framebuffer): viewport and
projection are those of a one-rank full render, so the pixels a rank produces are bit-identical
to that render's pixels in its region (llvmpipe bins triangles to the scissor, so work outside
the region is skipped). ``viewport`` (a region-sized framebuffer, shifted viewport) and
``offaxis`` (the region's own frustum) need less memory and reach bigger walls, at the price of
a few differing edge pixels. docs/ACCURACY.md measures all three.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multigpu.core.camera import model_view, region_clip
from multigpu.core.drawlist import DrawList, pass_groups
from multigpu.errors import InputError
from multigpu.gpu import texturing
from multigpu.gpu.buffers import can_pin, map_buffers, pack_vertices, pinned, upload
from multigpu.gpu.context import EGL_HELP, EglUnavailable, create_context, raster_threads  # noqa: F401 (their home)
from multigpu.gpu.methods import choose_method, gl_limits
from multigpu.gpu.morphs import MorphBuffers, SkinBuffers
from multigpu.gpu.pending import Pending, _disjoint
from multigpu.gpu.shaders import fragment_shader, vertex_shader

BACKGROUND = (0.08, 0.09, 0.12)


def ready_step(scene, shared: Path | None) -> tuple:
    """What ``RegionRenderer.rescene`` needs of a series' step beyond GL calls, made where it was
    read (a thread of its own): its draw list and its buffers file's maps, their pages mapped."""
    from multigpu.gpu.buffers import populate

    draws = DrawList(scene)
    maps = map_buffers(shared, scene, draws) if shared is not None else None
    if maps is not None:
        populate(maps)
    return draws, maps


class RegionRenderer:
    """Draws any subset of a scene's objects into any region of a ``size`` display.

    ``method`` picks how a region's pixels are made (see ``choose_method``); with ``scissor``
    they are bit-identical to a one-rank render of the whole display. ``colors``: the model's
    own (per-object colours, or its vertex colours where it has them) or ``objects``, a colour
    per object (``looks.palette``: what the balancer moves).
    """

    def __init__(self, ctx, scene, size: tuple[int, int], method: str = "auto", shared: Path | None = None,
                 colors: str = "model", moving: bool = False):
        import moderngl

        from multigpu.scene.looks import COLOR_VIEWS

        if colors not in COLOR_VIEWS:
            raise InputError.of("colors", f"must be one of {', '.join(COLOR_VIEWS)}, got '{colors}'")
        self.ctx = ctx
        self.size = W, H = size
        self.limits = gl_limits(ctx)
        self.method = choose_method(method, size, self.limits)
        per_vertex = colors == "model" and scene.vertex_colors is not None
        textured = colors == "model" and scene.texcoords is not None and scene.texels is not None
        self.texture_path = texturing.texture_path() if textured else None
        # a glTF model's morph targets (``morphs.py``), drawn by the moving program
        self.morphs = MorphBuffers(ctx, scene) if moving and scene.morph_rows is not None else None
        self.skins = SkinBuffers(ctx, scene) if moving and scene.skin_joints is not None else None
        program = lambda m: ctx.program(  # noqa: E731
            vertex_shader=vertex_shader(per_vertex, textured, m, m and self.morphs is not None,
                                        m and self.skins is not None),
            fragment_shader=fragment_shader(textured, self.texture_path))
        self.prog = program(moving)
        self.per_vertex, self.textured, self.colors = per_vertex, textured, colors
        self._load(scene, shared)
        # the programs a frame is drawn with: where the scene moves, the objects at rest (``pose``'s
        # ``groups``) go without the maps (their reads cost llvmpipe a quarter of a frame)
        self.passes, self._runs, self.groups = [(self.prog, self._array(self.prog, moving))], [(0, 0)], None
        if moving and not textured:
            still = program(False)
            self.passes.insert(0, (still, self._array(still, False)))
        self.texture, self.samplers, self.layers = (texturing.make(ctx, self.prog, scene, self.texture_path)
                                                    if textured else (None, [], None))
        # each object's map where the scene moves (``pose``), at rest till then
        self.mbo = ctx.buffer(np.tile(np.eye(3, 4, dtype=np.float32).ravel(), scene.n_objects)) if moving else None
        self.indirect = ctx.buffer(reserve=20 * 1024)  # grows when a frame needs more commands
        self.last_commands = 0  # draw commands of the last frame (runs of visible objects)
        self.fbo = None
        self.fbo_size = (0, 0)
        self._ring = None  # the scissor method's two framebuffers once a frame is submitted ahead (``submit``)
        self._tris = 0
        self._submits = 0  # frames submitted; a swapped-out step's buffers go ``keep`` frames after it
        self._retired: list = []  # (submits when they go, GL objects, the file maps they draw from)
        # the largest framebuffer side a region chunk may use
        self.chunk = self.limits["renderbuffer"]
        if self.method == "scissor":
            self._framebuffer((W, H))
        self.depth_test = moderngl.DEPTH_TEST

    def _load(self, scene, shared: Path | None, ready: tuple | None = None) -> None:
        """The scene's geometry into GL buffers (``_buffers``) and its objects' colours (``ready``:
        its draw list and buffers file maps, made ahead: ``ready_step``)."""
        from multigpu.scene.looks import palette

        self.origin = np.asarray(scene.origin, dtype=np.float64)
        self.draws, maps = ready if ready is not None else (DrawList(scene), None)
        bufs = self._buffers(scene, shared, self.per_vertex, self.textured, self.texture_path == "pool", maps)
        self.vbo, self.ibo, self.obo = bufs["vertices"], bufs["indices"], bufs["objects"]
        self.rgba, self.uvl, self.texels = bufs.get("colors"), bufs.get("texcoords"), bufs.get("texels")
        self._texel_bytes = 4 * int(scene.texels.shape[0]) if self.textured else 0
        self.draws.uploaded()  # the GL buffers hold them now: the frame loop keeps only the commands' tables
        object_colors = scene.colors if self.colors == "model" else palette(scene.n_objects)
        self.cbo = self.ctx.buffer(np.ascontiguousarray(object_colors, dtype=np.float32).ravel())

    def _array(self, prog, m: bool):
        """The vertex array of ``prog`` over the geometry's buffers (``m``: the moving program's)."""
        per_vertex, textured = self.per_vertex, self.textured
        return self.ctx.vertex_array(prog, [
            (self.vbo, "3f 1u", "in_pos", "in_nrm"), *([(self.rgba, "1u", "in_rgba")] if per_vertex else []),
            *([(self.obo, "1u", "in_obj")] if m or not per_vertex else []),
            *([(self.uvl, "3f", "in_uvl")] if textured else []),
            *([self.morphs.attribute()] if m and self.morphs is not None else []),
            *(self.skins.attributes() if m and self.skins is not None else [])],
            index_buffer=self.ibo, index_element_size=4)

    def rescene(self, scene, shared: Path | None = None, keep: int = 8, ready: tuple | None = None) -> None:
        """Draw ``scene`` from the next frame on: a series' next step, with the same kinds of vertex
        data (colours, no textures, no motion). Frames in flight were drawn from the old buffers
        (their storage may be a file's pages the GL reads as it draws): those go once ``keep`` more
        frames were submitted (frames in flight have been read by then), never stalling the GL.
        ``ready``: ``ready_step``'s, made in the thread that read the step."""
        if self.textured or self.mbo is not None:
            raise ValueError("a textured or moving scene's geometry is not swapped")
        old = (*(v for _, v in self.passes), self.vbo, self.ibo, self.obo, self.rgba, self.cbo)
        self._retired.append((self._submits + keep, old, self._maps))
        self._load(scene, shared, ready)
        self.passes = [(p, self._array(p, False)) for p, _ in self.passes]

    def restep(self, scene, keep: int = 8) -> None:
        """Draw ``scene`` from the next frame on where only its vertices and their colours differ
        from the scene drawn now (a series' step in its first step's layout: ``scene/same_cells.py``):
        the index, object and colour buffers and the draw list stay; the old vertex buffers go as
        ``rescene``'s do."""
        if self.textured or self.mbo is not None:
            raise ValueError("a textured or moving scene's geometry is not swapped")
        old = (*(v for _, v in self.passes), self.vbo, self.rgba)
        self._retired.append((self._submits + keep, old, None))  # (the file maps stay: the indices draw from them)
        self.origin = np.asarray(scene.origin, dtype=np.float64)
        self.vbo = upload(self.ctx, scene.vertices, 16, pack_vertices)
        if self.per_vertex:
            self.rgba = upload(self.ctx, scene.vertex_colors, 4)
        self.passes = [(p, self._array(p, False)) for p, _ in self.passes]

    def _retire(self) -> None:
        """Let go the geometry of steps whose frames have all been read (``rescene``)."""
        while self._retired and self._retired[0][0] <= self._submits:
            _, objects, _ = self._retired.pop(0)
            for obj in objects:
                if obj is not None:
                    obj.release()

    def _buffers(self, scene, shared: Path | None, per_vertex: bool, textured: bool, pool: bool,
                 maps: dict | None = None) -> dict:
        """The vertex, index and vertex-id GL buffers, the vertex colours' where they are drawn
        (``per_vertex``), the texture coordinates' (``textured``) and the texel pool's (``pool``),
        by name: the host's shared
        buffers file itself where the driver draws from host memory (``buffers.pinned``), else
        uploaded a block at a time (from that file where there is one: already packed).
        ``self.storage`` says which."""
        ctx, draws = self.ctx, self.draws
        if maps is None:
            maps = map_buffers(shared, scene, draws) if shared is not None else None
        self._maps = None
        names = ("vertices", "indices", "objects", *(("colors",) if per_vertex else ()),
                 *(("texcoords",) if textured else ()), *(("texels",) if pool else ()))
        if maps is None:
            self.storage = "uploaded" if shared is None else f"uploaded ({shared.name} does not fit this scene)"
        else:
            why = can_pin(ctx)
            if why is None:
                bufs = [pinned(ctx, maps[k]) for k in names]
                if all(b is not None for b in bufs):
                    self._maps, self.storage = maps, f"shared: {shared}"
                    return dict(zip(names, bufs))
                for b in bufs:
                    if b is not None:
                        b.release()
                why = "the driver refused host memory"
            self.storage = f"uploaded from {shared.name} ({why})"
            return {k: upload(ctx, maps[k], 16 if k == "vertices" else 12 if k == "texcoords" else 4) for k in names}
        ibo = ctx.buffer(reserve=max(4, 4 * draws.total))
        for at, block in draws.index_blocks():
            ibo.write(block, offset=4 * at)
        out = {"vertices": upload(ctx, scene.vertices, 16, pack_vertices), "indices": ibo,
               "objects": ctx.buffer(draws.vertex_object)}
        if per_vertex:
            out["colors"] = upload(ctx, scene.vertex_colors, 4)
        if textured:
            out["texcoords"] = upload(ctx, scene.texcoords, 12)
        if pool:
            out["texels"] = upload(ctx, scene.texels, 4)
        return out

    def _framebuffer(self, need: tuple[int, int]) -> None:
        """Make the framebuffer at least ``need`` (grown by 1/4 to avoid re-allocating often)."""
        fw, fh = self.fbo_size
        if need[0] <= fw and need[1] <= fh:
            return
        if self.method != "scissor":
            grow = lambda n, f: min(self.chunk, max(n, f, n * 5 // 4))
            need = (grow(need[0], fw), grow(need[1], fh))
        if self.fbo is not None:
            for att in (*self.fbo.color_attachments, self.fbo.depth_attachment):
                att.release()
            self.fbo.release()
        self.fbo = self._new_framebuffer(need)
        self.fbo_size = need

    def _new_framebuffer(self, size: tuple[int, int]):
        ctx = self.ctx
        return ctx.framebuffer(color_attachments=[ctx.renderbuffer(size, 4)],
                               depth_attachment=ctx.depth_renderbuffer(size))

    def _chunks(self, region, size: tuple[int, int]):
        """The region of a ``size`` display cut into pieces no larger than the framebuffer limit
        (usually one)."""
        x0, y0, x1, y1 = region
        c = self.chunk if self.method != "scissor" else max(size)
        for cy in range(y0, y1, c):
            for cx in range(x0, x1, c):
                yield cx, cy, min(cx + c, x1), min(cy + c, y1)

    def _commands(self, mask, seen, levels) -> np.ndarray:
        """The draw commands of the objects in ``mask`` (of their ``seen`` parts) at their ``levels``
        of detail (None: as modelled), each group's in turn (``groups``, ``_runs``: (pass, commands));
        ``_tris``: their triangles."""
        if self.groups is None:  # every object through the last pass (all move, or none does)
            cmds = self.draws.leveled(mask, levels, seen)
            self._runs = [(len(self.passes) - 1, len(cmds))]
        else:
            runs = [self.draws.leveled(g if mask is None else mask & g, levels, seen) for g, _ in self.groups]
            cmds = np.concatenate(runs)
            self._runs = [(p, len(r)) for (_, p), r in zip(self.groups, runs)]
        self.last_commands = len(cmds)
        self._tris = int(cmds[:, 0].sum()) // 3
        return cmds

    def _draw(self, cmds: np.ndarray, view, proj, light, scissor) -> None:
        """``cmds`` into the full-display framebuffer, scissored (the scissor method)."""
        mvp = np.asarray(proj, dtype=np.float64) @ model_view(view, self.origin)
        self.fbo.use()
        self.fbo.viewport = (0, 0, *self.size)
        self.fbo.scissor = scissor
        self.ctx.enable(self.depth_test)
        self.fbo.clear(*BACKGROUND, 1.0, depth=1.0)
        if len(cmds):
            self._upload(cmds, light)
            self._issue(mvp)

    def _issue(self, mvp) -> None:
        """The uploaded commands drawn, each group's with its pass's program (``_runs``)."""
        first, m = 0, np.ascontiguousarray(mvp.T, dtype=np.float32)
        for p, n in self._runs:  # a few groups
            prog, vao = self.passes[p]
            if n:
                prog["mvp"].write(m)
                vao.render_indirect(self.indirect, count=n, first=first)
            first += n

    def _upload(self, cmds: np.ndarray, light) -> None:
        """A frame's draw commands into the indirect buffer, the light and the colours bound."""
        if cmds.nbytes > self.indirect.size:
            self.indirect.orphan(cmds.nbytes)
        self.indirect.write(cmds)
        for prog, _ in self.passes:  # one or two
            prog["light"].value = tuple(float(v) for v in light)
        self.cbo.bind_to_storage_buffer(0)
        if self.mbo is not None:
            self.mbo.bind_to_storage_buffer(4)
        if self.morphs is not None:
            self.morphs.bind(self.prog)
        if self.skins is not None:
            self.skins.bind()
        if self.texture is not None:
            self.layers.bind_to_storage_buffer(1)
            if self.texels is not None:  # the pool: its level table and texels (a pinned buffer's
                self.texture.bind_to_storage_buffer(2)  # size is the file's, not the one moderngl knows)
                self.texels.bind_to_storage_buffer(3, size=self._texel_bytes)
            for unit, sampler in enumerate(self.samplers):
                sampler.use(unit)

    def render(self, view: np.ndarray, proj: np.ndarray, light: np.ndarray, region, mask: np.ndarray | None,
               depth: bool = False, seen: np.ndarray | None = None, scale: float = 1.0, levels=None):
        """Render the objects in ``mask`` (all when None) into ``region``; return its pixels.
        ``seen``: of a scene cut into parts, the parts that reach the region (``core/culling.py``;
        None: every part of the objects in ``mask``). ``scale`` and ``levels``: the frame's
        quality (``core/quality.py``): its render scale and each object's level of detail
        ((N,), None: all as modelled).

        Returns ``(h, w, 3)`` uint8, row 0 at the BOTTOM of the region (GL order); with
        ``depth`` also the ``(h, w)`` float32 window depth. ``last_triangles`` is what it drew.
        At a ``scale`` below 1 the region's footprint is drawn on the scaled canvas and brought
        back to the region's pixels (``core/resample.py``): each canvas pixel takes the one it
        shows, as a full render of the scaled canvas draws it.
        """
        if scale == 1.0:
            return self._pixels(view, proj, light, region, mask, depth, seen, levels, self.size)
        from multigpu.core.resample import footprint, scaled_size, upscale

        size = self.size
        small = scaled_size(size, scale)
        got = self._pixels(view, proj, light, footprint(region, size, small), mask, depth, seen, levels, small)
        if depth:
            return tuple(upscale(g, region, size, small) for g in got)
        return upscale(got, region, size, small)

    def _pixels(self, view, proj, light, region, mask, depth: bool, seen, levels, size: tuple[int, int]):
        """``render`` at scale 1 of a ``size`` display (the canvas, or its scaled one)."""
        x0, y0, x1, y1 = (int(v) for v in region)
        w, h = x1 - x0, y1 - y0
        cmds = self._commands(mask, seen, levels)
        self.last_triangles = self._tris
        ctx = self.ctx
        mvp = np.asarray(proj, dtype=np.float64) @ model_view(view, self.origin)
        if len(cmds):
            self._upload(cmds, light)
        out = np.empty((h, w, 3), dtype=np.uint8)
        zout = np.empty((h, w), dtype=np.float32) if depth else None
        W, H = size
        for cx0, cy0, cx1, cy1 in self._chunks((x0, y0, x1, y1), size):
            cw, ch = cx1 - cx0, cy1 - cy0
            if self.method == "scissor":
                fx, fy, viewport, m = cx0, cy0, (0, 0, W, H), mvp
            else:
                self._framebuffer((cw, ch))
                fx = fy = 0
                if self.method == "viewport":
                    viewport, m = (-cx0, -cy0, W, H), mvp
                else:
                    viewport, m = (0, 0, cw, ch), region_clip((cx0, cy0, cx1, cy1), size) @ mvp
            self.fbo.use()
            self.fbo.viewport = viewport
            self.fbo.scissor = (fx, fy, cw, ch)
            ctx.enable(self.depth_test)
            self.fbo.clear(*BACKGROUND, 1.0, depth=1.0)
            if len(cmds):
                self._issue(m)
            if (cw, ch) == (w, h):  # one chunk (the usual): read straight into the result, no copy
                self.fbo.read_into(out, viewport=(fx, fy, cw, ch), components=3, alignment=1)
                if depth:
                    self.fbo.read_into(zout, viewport=(fx, fy, cw, ch), components=1, attachment=-1, dtype="f4",
                                       alignment=1)
                continue
            rows, cols = slice(cy0 - y0, cy1 - y0), slice(cx0 - x0, cx1 - x0)
            data = self.fbo.read(viewport=(fx, fy, cw, ch), components=3, alignment=1)
            out[rows, cols] = np.frombuffer(data, dtype=np.uint8).reshape(ch, cw, 3)
            if depth:
                data = self.fbo.read(viewport=(fx, fy, cw, ch), components=1, attachment=-1, dtype="f4", alignment=1)
                zout[rows, cols] = np.frombuffer(data, dtype=np.float32).reshape(ch, cw)
        return (out, zout) if depth else out

    def submit(self, view: np.ndarray, proj: np.ndarray, light: np.ndarray, pieces: list, depth: bool = False,
               ahead: bool = False, scale: float = 1.0, levels=None) -> "Pending":
        """Draw a frame's ``pieces`` ``(region, mask, seen)`` now and read their pixels later
        (``Pending.read``: the same pixels ``render`` gives, piece by piece). ``ahead``: the
        caller submits the next frame before it reads this one (``--latency`` 2 and more), so the
        pieces go into the next framebuffer of a ring of two: the GL draws this frame while the
        rank's thread composes the last (llvmpipe rasterizes one framebuffer's scene while the
        next one's triangles are binned; a GPU draws while the CPU plans). Only the scissor
        method with disjoint pieces in one chunk each can wait; others are read at once.
        ``scale`` and ``levels``: the frame's quality, as ``render``'s."""
        self._submits += 1
        if self._retired:
            self._retire()
        if self._ring is not None:  # the other framebuffer than the last frame's (it may be unread yet)
            self._ring.reverse()
            self.fbo = self._ring[0]
        if not (ahead and self.method == "scissor" and scale == 1.0 and _disjoint([r for r, _, _ in pieces])):
            got, total = [], 0
            for r, m, s in pieces:  # pieces, not objects
                got.append(self.render(view, proj, light, r, m, depth, s, scale, levels))
                total += self._tris
            self.last_triangles = total
            return Pending([g if depth else (g, None) for g in got])
        if self._ring is None:
            self._ring = [self._new_framebuffer(self.size), self.fbo]
            self.fbo = self._ring[0]
        drawn, total = [], 0
        for region, mask, seen in pieces:  # pieces, not objects
            x0, y0, x1, y1 = (int(v) for v in region)
            self._draw(self._commands(mask, seen, levels), view, proj, light, (x0, y0, x1 - x0, y1 - y0))
            total += self._tris
            drawn.append((x0, y0, x1 - x0, y1 - y0))
        self.last_triangles = total
        return Pending(None, self.fbo, drawn, depth)

    def pose(self, rows: np.ndarray | None, movers: np.ndarray | None = None, weights=None, morph_of=None,
             palette=None) -> None:
        """Every object's (N, 12) float32 map (``core.motion``) from now on; frames still being drawn
        keep theirs (the buffer is orphaned first; ``rows`` None: ``pose_span`` writes them, every
        span before the next frame is drawn). ``movers``: (N,) bool, the objects that may
        move (the others are drawn without their maps); None keeps the last. ``weights``, ``morph_of``:
        a model's morph target weights, and each object's (``morphs.MorphBuffers.update``);
        ``palette``: its skins' joint maps."""
        if self.morphs is not None:
            self.morphs.update(weights, morph_of)
        if self.skins is not None:
            self.skins.update(palette)
        self.mbo.orphan()
        if rows is not None:
            self.mbo.write(rows)
        if movers is not None:  # one program for both (a textured scene's) keeps the groups' order
            got = pass_groups(self.draws.wide, np.asarray(movers, dtype=bool))
            self.groups = None if got is None else [(g, min(p, len(self.passes) - 1)) for g, p in got]

    def pose_span(self, rows: np.ndarray, lo: int) -> None:
        """Objects lo:lo + len(rows)'s maps, after ``pose(None, ...)``."""
        self.mbo.write(rows, offset=lo * rows.itemsize * 12)

    @property
    def framebuffer_bytes(self) -> int:
        """Colour + depth bytes of the framebuffer this renderer holds now."""
        return self.fbo_size[0] * self.fbo_size[1] * 8

    def release(self) -> None:
        for fbo in self._ring or [self.fbo]:
            if fbo is not None:
                for att in (*fbo.color_attachments, fbo.depth_attachment):
                    att.release()
                fbo.release()
        for obj in (*(v for _, v in self.passes), self.indirect, self.mbo, self.cbo, self.ibo, self.obo, self.rgba,
                    self.uvl, self.texels, self.vbo, *self.samplers, self.texture, self.layers,
                    *(p for p, _ in self.passes)):
            if obj is not None:
                obj.release()
        for extra in (self.morphs, self.skins):
            if extra is not None:
                extra.release()
        self._maps = None  # the file's maps outlive the GL buffers drawing from them
        self._submits += 1 << 30
        self._retire()

