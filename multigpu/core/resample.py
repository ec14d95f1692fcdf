"""Render scale: a frame drawn on fewer pixels and brought back to the tile's, the same on every rank.

At scale ``s`` the canvas (W, H) is drawn as a ``scaled_size`` canvas (sW, sH): the same camera,
fewer pixels. Canvas pixel ``x`` shows scaled pixel ``x * sW // W`` (nearest neighbour, integer
arithmetic), so the picture depends on the scale and the camera only, never on how the wall is
cut into regions: a rank draws the scaled pixels its region needs (``footprint``) and brings
them to its region's pixels (``upscale``), and the composite equals one rank's scaled render
brought to the canvas, bit for bit. A scaled pixel's sample may lie a little outside the region
whose pixels show it, so a rank draws the objects that reach the canvas area its scaled pixels
cover (``covered``), not only its region's (``Widen``); a sort-last piece, whose objects are
its own wherever they fall, grows instead (``grown``). Pure numpy.
"""

from __future__ import annotations

import numpy as np

from multigpu.core.regions import overlaps, pixel_spans

#: the smallest render scale (a sixteenth of the pixels)
MIN_SCALE = 0.25


def scaled_size(size: tuple[int, int], scale: float) -> tuple[int, int]:
    """(sW, sH): the canvas ``size`` at ``scale`` (at least a pixel a side)."""
    return max(1, int(round(size[0] * scale))), max(1, int(round(size[1] * scale)))


def footprint(region, size: tuple[int, int], ssize: tuple[int, int]) -> tuple[int, int, int, int]:
    """The scaled pixels ``[sx0, sy0, sx1, sy1)`` that canvas ``region`` ``[x0, y0, x1, y1)`` shows."""
    x0, y0, x1, y1 = (int(v) for v in region)
    (W, H), (sW, sH) = size, ssize
    return x0 * sW // W, y0 * sH // H, (x1 - 1) * sW // W + 1, (y1 - 1) * sH // H + 1


def covered(region, size: tuple[int, int], ssize: tuple[int, int]) -> tuple[int, int, int, int]:
    """The canvas pixels ``[x0, y0, x1, y1)`` that the scaled pixels of ``region``'s footprint
    cover (a superset of ``region``): where their samples may lie."""
    sx0, sy0, sx1, sy1 = footprint(region, size, ssize)
    (W, H), (sW, sH) = size, ssize
    return sx0 * W // sW, sy0 * H // sH, -(-sx1 * W // sW), -(-sy1 * H // sH)


def upscale(small: np.ndarray, region, size: tuple[int, int], ssize: tuple[int, int]) -> np.ndarray:
    """``region``'s pixels (h, w, ...) from its footprint's scaled pixels ``small`` (row 0 at the
    bottom, as the GL reads them): each canvas pixel takes the scaled pixel it shows."""
    x0, y0, x1, y1 = (int(v) for v in region)
    sx0, sy0, _, _ = footprint(region, size, ssize)
    (W, H), (sW, sH) = size, ssize
    rows = np.arange(y0, y1, dtype=np.int64) * sH // H - sy0
    cols = np.arange(x0, x1, dtype=np.int64) * sW // W - sx0
    return small.take(rows, axis=0).take(cols, axis=1)


def grown(rects: np.ndarray, size: tuple[int, int], scale: float, skip: int = 0) -> np.ndarray:
    """Sort-last pieces (M, 4) grown by the span of a scaled pixel (and one more) on every side,
    within the canvas: a canvas pixel outside a piece may show a scaled pixel whose sample lies
    inside it, and the composite takes each pixel's nearest fragment from every piece that has it.
    The first ``skip`` pieces (a hybrid's screen regions, which tile the canvas) stay as they are."""
    g = int(np.ceil(1.0 / scale)) + 1
    r = np.asarray(rects, dtype=np.int64).reshape(-1, 4).copy()
    W, H = size
    r[skip:] = np.clip(r[skip:] + np.array([-g, -g, g, g]), 0, [W, H, W, H])
    return r


class Widen:
    """The masks of a frame's pieces widened to the objects that reach what their scaled pixels
    cover (``covered``), in the visible space where the plan was made (``canvas.to_visible``)."""

    def __init__(self, canvas):
        self.canvas = canvas

    def masks(self, rects: np.ndarray, masks, vrects: np.ndarray, scale: float, crects=None) -> list:
        """``masks`` of the canvas pieces ``rects`` (M, 4) widened for ``scale``; ``vrects``: this
        frame's normalized visible object rects; ``crects``: the same on the canvas, where there are
        bezels (then the widening is found there: a scaled pixel at a tile's edge may show an object
        wholly behind the bezel beside it, which has no visible rect)."""
        canvas = self.canvas
        size, vis = canvas.size, canvas.visible
        ssize = scaled_size(size, scale)
        if crects is not None:
            spans, on = pixel_spans(crects, size)
            return [mask | (on & overlaps(spans, covered(rect, size, ssize))) for rect, mask in zip(rects, masks)]
        spans, on = pixel_spans(vrects, vis)
        out = []
        for rect, mask in zip(rects, masks):  # pieces, not objects
            cx0, cy0, cx1, cy1 = covered(rect, size, ssize)
            norm = np.array([[cx0 / size[0], cy0 / size[1], cx1 / size[0], cy1 / size[1]]])
            v = canvas.to_visible(norm)[0]
            if not np.isfinite(v).all():  # wholly behind a bezel: nothing more to draw
                out.append(mask)
                continue
            px = v * np.array([vis[0], vis[1], vis[0], vis[1]])  # whole pixels, give or take the rounding
            area = (int(np.floor(px[0] + 1e-6)), int(np.floor(px[1] + 1e-6)), int(np.ceil(px[2] - 1e-6)),
                    int(np.ceil(px[3] - 1e-6)))
            out.append(mask | (on & overlaps(spans, area)))
        return out
