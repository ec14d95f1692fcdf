"""A projector rig described by its geometry, and what it puts on its screen.

Projectors (pinholes: a position, a heading, a throw ratio and a lens shift, a resolution) light a
flat screen or a cylindrical one (a vertical arc around the viewer). From the geometry alone this
module makes each projector's *output*: its warp (every pixel's point of the content,
output-to-content, NaN off the screen), its blend ``alpha`` (each pixel's share of the light where
projectors overlap: weights falling to zero at every projector's edge, normalized so that the
shares at any screen point sum to one) and ``beta`` (the black-level lift that makes a black frame
as bright everywhere as where the most projectors overlap). ``multigpu warp make`` writes these as
an MPCDI file; the tests and ``bench projectors`` *simulate the projection*: each screen point's
light is the sum over the projectors that reach it of their output's light there, through a
display gamma and a black floor, to be compared with the content shown straight.

Coordinates: the screen's content is (s, t) in 0..1, s to the right and t down. World: y up, the
viewer at the origin looking down -z; a flat screen lies in the plane z = -distance. Pure numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multigpu.core.warpblend import GAMMA, decode, grid_points


@dataclass(frozen=True)
class Screen:
    """A flat screen (``kind='flat'``: ``width`` x ``height`` at ``distance`` in front of the
    viewer) or a cylindrical one (``'cylinder'``: radius ``distance``, ``arc`` degrees wide,
    ``height`` tall, centred in front of the viewer)."""

    kind: str = "flat"
    width: float = 4.0
    height: float = 1.5
    distance: float = 3.0
    arc: float = 120.0

    def __post_init__(self):
        if self.kind not in ("flat", "cylinder"):
            raise ValueError(f"screen must be 'flat' or 'cylinder', got '{self.kind}'")

    def point(self, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(..., 3) the world point of content (s, t)."""
        y = (0.5 - t) * self.height
        if self.kind == "flat":
            return np.stack(np.broadcast_arrays((s - 0.5) * self.width, y, -self.distance), axis=-1)
        phi = np.radians((s - 0.5) * self.arc)
        return np.stack(np.broadcast_arrays(self.distance * np.sin(phi), y, -self.distance * np.cos(phi)), axis=-1)

    def hit(self, origin: np.ndarray, ray: np.ndarray) -> np.ndarray:
        """(..., 2) the content (s, t) where rays from ``origin`` along ``ray`` (..., 3) meet the
        screen's surface (beyond its edges too: outside 0..1), NaN where they miss it or meet it
        behind the projector."""
        o = np.asarray(origin, dtype=np.float64)
        if self.kind == "flat":
            k = (-self.distance - o[2]) / ray[..., 2]
            p = o + k[..., None] * ray
            s, t = p[..., 0] / self.width + 0.5, 0.5 - p[..., 1] / self.height
        else:  # |(x, z)| = distance: the far root from a projector inside the cylinder
            a = ray[..., 0] ** 2 + ray[..., 2] ** 2
            b = 2 * (o[0] * ray[..., 0] + o[2] * ray[..., 2])
            c = o[0] ** 2 + o[2] ** 2 - self.distance ** 2
            with np.errstate(invalid="ignore", divide="ignore"):
                k = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
            p = o + k[..., None] * ray
            s = np.degrees(np.arctan2(p[..., 0], -p[..., 2])) / self.arc + 0.5
            t = 0.5 - p[..., 1] / self.height
        return np.where((k > 0)[..., None], np.stack([s, t], axis=-1), np.nan)


@dataclass(frozen=True)
class Projector:
    """A pinhole projector: at ``position``, turned ``yaw`` degrees to the left and ``pitch`` up
    from looking down -z, ``throw`` (distance over image width on a square-on wall), lens
    ``shift`` (x, y) in image widths and heights, ``size`` (w, h) pixels, named ``name``."""

    name: str
    position: tuple[float, float, float]
    yaw: float = 0.0
    pitch: float = 0.0
    throw: float = 1.5
    shift: tuple[float, float] = (0.0, 0.0)
    size: tuple[int, int] = (256, 192)

    def turn(self) -> np.ndarray:
        """(3, 3) the projector's frame in the world (columns: right, up, back)."""
        y, p = np.radians(self.yaw), np.radians(self.pitch)
        yaw = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
        pitch = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
        return yaw @ pitch

    def rays(self, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        """(..., 3) world directions through pixel coordinates (px right, py down, pixel centres
        at +0.5)."""
        w, h = self.size
        f = self.throw * w
        x = (px - w / 2 - self.shift[0] * w) / f
        y = -(py - h / 2 + self.shift[1] * h) / f
        local = np.stack(np.broadcast_arrays(x, y, -1.0), axis=-1)
        return local @ self.turn().T

    def pixel(self, points: np.ndarray) -> np.ndarray:
        """(..., 2) the pixel coordinates where world ``points`` (..., 3) appear, NaN behind the
        projector or outside its image."""
        w, h = self.size
        f = self.throw * w
        local = (np.asarray(points) - np.asarray(self.position)) @ self.turn()
        with np.errstate(invalid="ignore", divide="ignore"):
            px = -local[..., 0] / local[..., 2] * f + w / 2 + self.shift[0] * w
            py = local[..., 1] / local[..., 2] * f + h / 2 - self.shift[1] * h
        ok = (local[..., 2] < 0) & (px >= 0) & (px <= w) & (py >= 0) & (py <= h)
        return np.where(ok[..., None], np.stack([px, py], axis=-1), np.nan)


@dataclass(frozen=True)
class Rig:
    """Projectors on a screen, and the black floor of each (its light at input 0, as a share
    of its light at input 255)."""

    screen: Screen
    projectors: tuple[Projector, ...]
    black: float = 0.002
    gamma: float = GAMMA
    ramp: float = 2.0  # the blend weights' power of the distance to the edge

    def warp(self, i: int, grid: tuple[int, int] | None = None) -> np.ndarray:
        """(rows, cols, 2) projector ``i``'s warp: the content at each sample, outside 0..1 beyond
        the screen's edges (every pixel centre
        where ``grid`` is None, else a grid of ``grid`` (rows, cols) samples spanning the pixel
        centres, as ``core.warpblend.upsample`` reads it)."""
        p = self.projectors[i]
        w, h = p.size
        xs, ys = (np.arange(w) + 0.5, np.arange(h) + 0.5) if grid is None else grid_points(grid, p.size)
        px, py = np.meshgrid(xs, ys)
        return self.screen.hit(np.asarray(p.position, dtype=np.float64), p.rays(px, py))

    def edge(self, points: np.ndarray) -> np.ndarray:
        """(P, ...) each projector's distance (pixels) from world ``points`` to its image's
        nearest edge, 0 where it does not reach them."""
        out = []
        for p in self.projectors:
            uv = p.pixel(points)
            w, h = p.size
            d = np.minimum(np.minimum(uv[..., 0], w - uv[..., 0]), np.minimum(uv[..., 1], h - uv[..., 1]))
            out.append(np.nan_to_num(d, nan=0.0))
        return np.stack(out)

    def shares(self, points: np.ndarray) -> np.ndarray:
        """(P, ...) each projector's share of the light at world ``points``: weights that fall
        to zero at its image's edges, normalized to sum to one where any projector reaches."""
        wgt = self.edge(points) ** self.ramp
        total = wgt.sum(axis=0)
        return np.divide(wgt, total, out=np.zeros_like(wgt), where=total > 0)

    def covering(self, points: np.ndarray) -> np.ndarray:
        """(...) how many projectors reach each of the world ``points``."""
        return (self.edge(points) > 0).sum(axis=0)

    def most(self, samples: int = 256) -> int:
        """The most projectors that overlap anywhere on the screen (sampled)."""
        s, t = np.meshgrid(np.linspace(0, 1, samples), np.linspace(0, 1, samples // 2))
        return int(self.covering(self.screen.point(s, t)).max())

    def blend_maps(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """(h, w) projector ``i``'s ``alpha`` (its share of the light) and ``beta`` (the black
        lift: where k of the rig's most n projectors overlap, each of the k lifts its black by
        (n - k) black floors' worth, shared), linear, at every pixel; 0 off the screen."""
        st = self.warp(i)
        on = ((st >= 0) & (st <= 1)).all(axis=-1)  # NaN compares False: off the screen
        points = self.screen.point(np.nan_to_num(st[..., 0]), np.nan_to_num(st[..., 1]))
        alpha = np.where(on, self.shares(points)[i], 0.0)
        k = np.maximum(self.covering(points), 1)
        beta = np.where(on, (self.most() - k) * self.black / ((1 - self.black) * k), 0.0)
        return alpha, beta

    def light(self, outputs: list[np.ndarray], s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(..., C) the light at content points (s, t) of the screen: for every projector that
        reaches it, its output image (h, w, C) sampled there (bilinear), through its display
        gamma and black floor, summed."""
        from multigpu.core.warpblend import sample

        points = self.screen.point(s, t)
        total = 0.0
        for p, img in zip(self.projectors, outputs):
            uv = p.pixel(points)
            w, h = p.size
            coords = np.stack([uv[..., 0] / w, uv[..., 1] / h], axis=-1)
            seen = np.isfinite(coords[..., :1])
            value = sample(img, coords)
            total = total + np.where(seen, self.black + (1 - self.black) * decode(value, self.gamma), 0.0)
        return total


def flat_rig(n: int = 3, overlap: float = 0.18, size: tuple[int, int] = (256, 192), kind: str = "flat",
             black: float = 0.002, aspect: float | None = None) -> Rig:
    """``n`` projectors side by side lighting a screen (``kind``: flat or cylinder), neighbours
    overlapping by ``overlap`` of an image's width, each a little askew (turned and tilted a few
    degrees, lens shifted) so that no warp is a plain scale; their images overfill the screen
    above and below (the margins are off it). ``aspect``: the screen's width over its height (a
    wall's canvas's; default: 0.8 of the images' height)."""
    screen = Screen(kind)
    across = screen.width if kind == "flat" else np.radians(screen.arc) * screen.distance
    span = 1.06 * across  # overfilled
    each = span / (n - (n - 1) * overlap)  # an image's width on the screen
    tall = each * size[1] / size[0]
    high = 0.8 * tall if aspect is None else across / aspect
    if high > 0.95 * tall:
        raise ValueError(f"a screen of aspect {aspect:.3g} is taller than {n} projectors of {size[0]}x{size[1]} "
                         f"side by side can fill: use a wider canvas or more overlap")
    screen = Screen(kind, height=high)  # the images overfill it above and below
    projectors = []
    for i in range(n):
        centre = (i + 0.5) * each * (1 - overlap) + each * overlap / 2 - span / 2  # along the screen
        tilt, turn = (1.5, -2.0, 1.0, 2.5)[i % 4], (-1.0, 1.5, -2.0, 0.5)[i % 4]
        if kind == "flat":
            dist = 0.9 * screen.distance
            pos = (centre, 0.05 * (i % 2), -screen.distance + dist)
            yaw = turn
        else:  # from near the cylinder's axis, facing the arc at its own angle
            a = centre / screen.distance
            dist = 1.2 * screen.distance
            pos = (-0.2 * screen.distance * np.sin(a), 0.05 * (i % 2), 0.2 * screen.distance * np.cos(a))
            yaw = -np.degrees(a) + turn
        throw = dist / each
        projectors.append(Projector(f"p{i + 1}", pos, yaw=yaw, pitch=tilt, throw=throw,
                                    shift=(0.01 * (i - 1), 0.02), size=size))
    return Rig(screen, tuple(projectors), black=black)
