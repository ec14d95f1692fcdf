"""The calibration pattern of ``multigpu wall test``: one picture across the whole canvas, each
tile showing its part of it.

A grid, concentric circles and diagonals run across the mullions, so they look straight and
round across the bezels only when the mullion values are right; each tile names its rank, host,
display and size in large type; a bar moves across the canvas and every tile counts frames, so
tiles that do not swap together show a broken bar or different counts. Pure numpy and Pillow:
the same pixels on every rank and in tests.
"""

from __future__ import annotations

import numpy as np

GRID = 64  # pixels between grid lines
BACKGROUND = (24, 24, 32)
LINES = (200, 200, 200)
CIRCLES = (90, 200, 255)
DIAGONALS = (255, 180, 60)
BAR = (255, 60, 60)


def tile_pattern(canvas_size: tuple[int, int], origin: tuple[int, int], tile: tuple[int, int], frame: int,
                 label: list[str], ramp: bool = False) -> np.ndarray:
    """The (th, tw, 3) uint8 part of the canvas pattern a tile shows, top row first: the tile's
    top-left corner at canvas pixel ``origin`` (x right, y down) of a ``canvas_size`` canvas
    (mullions included); ``label``: the lines of type drawn in the tile's middle. ``ramp``: a
    grey ramp from black to white across the canvas in a band above the middle (a projector
    wall's: through the blend it must run on smoothly where projectors overlap)."""
    W, H = canvas_size
    tw, th = tile
    x = np.arange(origin[0], origin[0] + tw, dtype=np.float64)[None, :] + 0.5  # pixel centres
    y = np.arange(origin[1], origin[1] + th, dtype=np.float64)[:, None] + 0.5
    img = np.empty((th, tw, 3), dtype=np.uint8)
    img[:] = BACKGROUND
    grid = (np.floor(x) % GRID == 0) | (np.floor(y) % GRID == 0) | (np.floor(x) == W - 1) | (np.floor(y) == H - 1)
    img[np.broadcast_to(grid, (th, tw))] = LINES
    cx, cy = W / 2.0, H / 2.0
    r = np.hypot(x - cx, y - cy)
    step = max(min(W, H) / 8.0, 8.0)
    img[np.abs(r - np.round(r / step) * step) < 1.0] = CIRCLES
    diag = np.hypot(W, H)
    for a, b in (((0.0, 0.0), (W, H)), ((W, 0.0), (0.0, H))):  # the canvas's two diagonals
        d = np.abs((b[0] - a[0]) * (a[1] - y) - (a[0] - x) * (b[1] - a[1])) / diag
        img[d < 1.0] = DIAGONALS
    if ramp:
        band = (y >= 0.2 * H) & (y < 0.3 * H)
        grey = np.broadcast_to(np.round(255.0 * (x - 0.5) / max(W - 1, 1)), (th, tw))
        img[np.broadcast_to(band, (th, tw))] = np.repeat(grey[np.broadcast_to(band, (th, tw))][:, None], 3, axis=1)
    bar_x = (frame * 8) % max(W, 1)  # the moving bar: 8 pixels a frame across the canvas
    img[np.broadcast_to((x >= bar_x) & (x < bar_x + 12), (th, tw))] = BAR
    return _type(img, [*label, f"frame {frame}"])


#: the depth test's marks, from far to near: their disparities in steps (the right eye's mark sits
#: this many steps to the left of the left eye's: crossed disparity, in front of the wall, for > 0)
DEPTHS = (-2, -1, 0, 1, 2)
DEPTH_COLOURS = ((60, 90, 255), (60, 200, 255), (240, 240, 240), (255, 200, 60), (255, 80, 60))


def stereo_tile_pattern(stereo, rank: int, frame: int, label: list[str]) -> np.ndarray:
    """What tile ``rank`` of a ``stereo`` wall (``core.stereo.Stereo``) shows, bottom row first:
    each eye's part of the pattern on that eye's canvas, named for the eye (a different mark in
    each: the LEFT and RIGHT squares), with a depth test across the tile's lower part (squares
    from far behind the wall to near in front of it: each a disparity of ``DEPTHS`` steps), then
    packed as the display shows it (side by side, top and bottom, anaglyph)."""
    eye = stereo.eye
    ew, eh = stereo.eye_tile
    x0, _, _, y1 = (int(v) for v in eye.tiles()[rank])
    step = max(2, ew // 48)
    side = max(4, min(ew // (2 * len(DEPTHS) + 1), eh // 6))
    halves = []
    for e, name in enumerate(("LEFT", "RIGHT")):
        img = tile_pattern(eye.size, (x0, eye.size[1] - y1), (ew, eh), frame, [*label, f"{name} eye"]).copy()
        mark = (8, 8) if e == 0 else (ew - 8 - side, 8)  # each eye's own mark: a square in its own top corner
        img[mark[1]:mark[1] + side, mark[0]:mark[0] + side] = (0, 255, 0) if e == 0 else (255, 0, 255)
        top = eh - side - max(4, eh // 12)
        for i, (d, colour) in enumerate(zip(DEPTHS, DEPTH_COLOURS)):  # five marks
            cx = (2 * i + 1) * ew // (2 * len(DEPTHS)) + (d * step // 2 if e == 0 else -(d * step // 2))
            xa = int(np.clip(cx - side // 2, 0, ew - side))
            img[top:top + side, xa:xa + side] = colour
        halves.append(img[::-1])  # bottom row first
    return stereo.pack(np.concatenate(halves, axis=1))


def _type(img: np.ndarray, lines: list[str]) -> np.ndarray:
    """``lines`` in large type centred on ``img`` (a box behind them, so they read on lines)."""
    from PIL import Image, ImageDraw, ImageFont

    th, tw = img.shape[:2]
    size = max(8, min(th // (2 * len(lines) + 2), tw // 14))
    font = ImageFont.load_default(size=size)
    pic = Image.fromarray(img)
    draw = ImageDraw.Draw(pic)
    boxes = [draw.textbbox((0, 0), s, font=font) for s in lines]
    height = sum(b[3] - b[1] for b in boxes) + size // 2 * (len(lines) - 1)
    y = (th - height) // 2
    width = max(b[2] - b[0] for b in boxes)
    draw.rectangle(((tw - width) // 2 - 6, y - 6, (tw + width) // 2 + 6, y + height + 6), fill=(0, 0, 0))
    for s, b in zip(lines, boxes):  # a few lines of type
        draw.text(((tw - (b[2] - b[0])) // 2 - b[0], y - b[1]), s, fill=(255, 255, 255), font=font)
        y += b[3] - b[1] + size // 2
    return np.asarray(pic)


def nudge(mullion: tuple[int, int], key: str) -> tuple[int, int]:
    """The mullions after a key press: Left/Right one pixel less/more between columns, Down/Up
    between rows (never below 0)."""
    mx, my = mullion
    mx += {"left": -1, "right": 1}.get(key, 0)
    my += {"down": -1, "up": 1}.get(key, 0)
    return max(mx, 0), max(my, 0)
