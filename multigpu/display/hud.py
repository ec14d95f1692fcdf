"""What is drawn over the picture: the partition (each rank's pieces tinted and outlined) and a
statistics panel (FPS, per-rank balance/render/exchange bars, imbalance, the strategy).

Pure image work (numpy, Pillow's text), no GL and no MPI: the mosaics' partition images, the
live overlays on the wall's tiles and the operator's monitor all draw with these. Images are
top row first unless a function says otherwise.
"""

from __future__ import annotations

import numpy as np

PALETTE = np.array([[230, 25, 75], [60, 180, 75], [255, 225, 25], [0, 130, 200], [245, 130, 48],
                    [145, 30, 180], [70, 240, 240], [240, 50, 230], [210, 245, 60], [250, 190, 212],
                    [0, 128, 128], [220, 190, 255], [170, 110, 40], [255, 250, 200], [128, 0, 0],
                    [170, 255, 195]], dtype=np.float32)
#: the statistics panel's bar colours: balancing, rendering, exchange
PHASE_COLOURS = ((255, 200, 40), (80, 200, 120), (90, 150, 255))


def overlay(img: np.ndarray, rects, alpha: float = 0.18, origin=(0, 0), scale: int = 1) -> np.ndarray:
    """Tint each rank's pieces with its colour and outline them; ``rects[k]`` is rank k's
    (M_k, 4) pieces (or one (4,) region) in pixels of a picture whose bottom-left corner is
    ``origin`` (rects reaching outside ``img`` are clipped: a tile shows its share of a
    piece, outlined only where the piece really ends) and shrunk ``scale`` times."""
    H, W = img.shape[:2]
    out = img.astype(np.float32)
    ox, oy = origin
    boxes = [(k, r) for k, rs in enumerate(rects) for r in np.asarray(rs, dtype=np.int64).reshape(-1, 4)]
    for k, (x0, y0, x1, y1) in boxes:  # pieces, not objects
        x0, x1 = (x0 - ox) // scale, -(-(x1 - ox) // scale)
        top, bot = H - (-(-(y1 - oy) // scale)), H - (y0 - oy) // scale
        c0, c1, r0, r1 = max(x0, 0), min(x1, W), max(top, 0), min(bot, H)
        if c0 >= c1 or r0 >= r1:
            continue
        c = PALETTE[k % len(PALETTE)]
        out[r0:r1, c0:c1] = out[r0:r1, c0:c1] * (1 - alpha) + c * alpha
        edges = []
        if 0 <= x0 < W:
            edges.append(np.s_[r0:r1, c0:min(x0 + 2, c1)])
        if 0 < x1 <= W:
            edges.append(np.s_[r0:r1, max(x1 - 2, c0):c1])
        if 0 <= top < H:
            edges.append(np.s_[r0:min(top + 2, r1), c0:c1])
        if 0 < bot <= H:
            edges.append(np.s_[max(bot - 2, r0):r1, c0:c1])
        for sl in edges:
            out[sl] = c
    return out.astype(np.uint8)


def stats_panel(fps: float, balance: str, phases: np.ndarray, triangles: np.ndarray, mode: str,
                width: int = 220, quality: str = "", restarts: int = 0) -> np.ndarray:
    """The statistics panel as an RGB image: a line of FPS, strategy and mode (and ``quality``:
    the frame's render scale and LOD bound where below full), a line of
    imbalance, then one bar per rank with its balancing, rendering and exchange milliseconds
    (``phases``, (K, 3)) stacked to scale, and the scale; after a recovery (``restarts``) a last
    line says how often the wall was restarted."""
    from PIL import Image, ImageDraw, ImageFont

    K = len(phases)
    bar, pad, line = 7, 4, 12
    height = pad * 2 + line * (3 + bool(restarts)) + K * (bar + 2)
    img = Image.new("RGB", (width, height), (16, 16, 24))
    draw = ImageDraw.Draw(img)
    font = ImageFont.load_default()
    mean = float(np.mean(triangles)) if K else 0.0
    imbalance = float(np.max(triangles)) / mean if mean > 0 else 1.0
    draw.text((pad, pad), f"{fps:5.1f} fps  {balance}  {mode}{quality}", fill=(240, 240, 240), font=font)
    draw.text((pad, pad + line), f"imbalance {imbalance:.2f} (max/mean triangles)", fill=(200, 200, 200), font=font)
    total = np.sum(phases, axis=1)
    top = max(float(total.max()) if K else 0.0, 1e-6)
    span = width - 2 * pad - 28
    y = pad + 2 * line + 2
    for k in range(K):  # ranks, not objects
        draw.text((pad, y - 3), f"{k}", fill=tuple(int(v) for v in PALETTE[k % len(PALETTE)]), font=font)
        x = pad + 14
        for ms, colour in zip(phases[k], PHASE_COLOURS):
            w = int(round(span * float(ms) / top))
            if w > 0:
                draw.rectangle([x, y, x + w - 1, y + bar - 1], fill=colour)
            x += w
        y += bar + 2
    draw.text((pad, y), f"bar = {top:.1f} ms: balance render exchange", fill=(170, 170, 170), font=font)
    if restarts:
        draw.text((pad, y + line), f"recovered: restarted {restarts}x", fill=(255, 170, 60), font=font)
    return np.asarray(img)


def paste(tile: np.ndarray, panel: np.ndarray, alpha: float = 0.85) -> np.ndarray:
    """``panel`` (top row first) blended into the top-left corner of a bottom-up ``tile``."""
    out = tile.copy()
    h, w = min(panel.shape[0], tile.shape[0]), min(panel.shape[1], tile.shape[1])
    region = out[tile.shape[0] - h:, :w]
    src = panel[:h, :w][::-1].astype(np.float32)
    out[tile.shape[0] - h:, :w] = (region * (1 - alpha) + src * alpha).astype(np.uint8)
    return out
