"""A projector output's warp and blend: the content it shows, where, and how bright.

A projector never lands square on its screen, and neighbours overlap. Its *warp* says, for
every output pixel, which point of the content it must show: a grid of normalized content
coordinates (x right, y down, 0..1 across the content; NaN where the pixel shows nothing),
output-to-content as MPCDI's 2D media profile stores it, usually coarser than the output and
interpolated linearly between its samples. Its *blend* says how much light each pixel gives:
MPCDI's ``P * alpha * (1 - beta) + beta`` in linear light, ``alpha`` fading a projector out
where a neighbour fades in (the alphas of an overlap sum to one) and ``beta`` lifting the black
level where fewer projectors overlap, so a black frame is one grey everywhere. The output's
display gamma is taken off before and put back after: blending gamma-encoded values instead
(as most tools do by default) dims an overlap's centre by half and more.

Pure numpy (the run's final pass does the same arithmetic on the GPU or the CPU): sampling a
warp grid, sampling content through it, and the blend.
"""

from __future__ import annotations

import numpy as np

#: a display's usual gamma (sRGB's is close to it): 8-bit values to light and back
GAMMA = 2.2


def decode(values: np.ndarray, gamma: float = GAMMA) -> np.ndarray:
    """8-bit display values to linear light in 0..1."""
    return (np.asarray(values, dtype=np.float64) / 255.0) ** gamma


def encode(light: np.ndarray, gamma: float = GAMMA) -> np.ndarray:
    """Linear light in 0..1 to 8-bit display values (rounded, clipped)."""
    return np.clip(np.round(255.0 * np.clip(light, 0.0, 1.0) ** (1.0 / gamma)), 0, 255).astype(np.uint8)


def grid_points(grid_shape: tuple[int, int], size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Where a warp grid of ``grid_shape`` (rows, cols) samples an output of ``size`` (w, h):
    its first and last samples on the first and last pixels' centres, the others evenly
    between, as (cols,) x and (rows,) y pixel-centre coordinates."""
    rows, cols = grid_shape
    w, h = size
    return np.linspace(0.5, w - 0.5, cols), np.linspace(0.5, h - 0.5, rows)


def upsample(grid: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(h, w, 2): a warp ``grid`` (rows, cols, 2) at every pixel centre of an output of ``size``
    (w, h), interpolated linearly between its samples; NaN wherever a sample it leans on is NaN
    (an output pixel shows content only where the whole cell around it does)."""
    grid = np.asarray(grid, dtype=np.float64)
    rows, cols = grid.shape[:2]
    w, h = size
    gx, gy = grid_points((rows, cols), size)
    px, py = np.arange(w) + 0.5, np.arange(h) + 0.5
    fx = np.interp(px, gx, np.arange(cols, dtype=np.float64)) if cols > 1 else np.zeros(w)
    fy = np.interp(py, gy, np.arange(rows, dtype=np.float64)) if rows > 1 else np.zeros(h)
    x0, y0 = np.minimum(fx.astype(np.int64), max(cols - 2, 0)), np.minimum(fy.astype(np.int64), max(rows - 2, 0))
    x1, y1 = np.minimum(x0 + 1, cols - 1), np.minimum(y0 + 1, rows - 1)
    tx, ty = (fx - x0)[None, :, None], (fy - y0)[:, None, None]
    g00, g01 = grid[y0][:, x0], grid[y0][:, x1]
    g10, g11 = grid[y1][:, x0], grid[y1][:, x1]
    return (g00 * (1 - tx) + g01 * tx) * (1 - ty) + (g10 * (1 - tx) + g11 * tx) * ty


def sample(content: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """(h, w, C) ``content`` (H, W, C), top row first, at normalized ``coords`` (h, w, 2),
    bilinear between pixel centres (clamped to the edge pixels), black where a coordinate is
    NaN or outside 0..1."""
    H, W = content.shape[:2]
    x, y = coords[..., 0] * W - 0.5, coords[..., 1] * H - 0.5
    inside = np.isfinite(x) & np.isfinite(y) & (coords[..., 0] >= 0) & (coords[..., 0] <= 1) & \
        (coords[..., 1] >= 0) & (coords[..., 1] <= 1)
    x, y = np.where(inside, np.clip(x, 0, W - 1), 0.0), np.where(inside, np.clip(y, 0, H - 1), 0.0)
    x0 = np.minimum(x.astype(np.int64), W - 2 if W > 1 else 0)
    y0 = np.minimum(y.astype(np.int64), H - 2 if H > 1 else 0)
    x1, y1 = np.minimum(x0 + 1, W - 1), np.minimum(y0 + 1, H - 1)
    tx, ty = (x - x0)[..., None], (y - y0)[..., None]
    c = np.asarray(content, dtype=np.float64)
    out = (c[y0, x0] * (1 - tx) + c[y0, x1] * tx) * (1 - ty) + (c[y1, x0] * (1 - tx) + c[y1, x1] * tx) * ty
    out[~inside] = 0.0
    return out


def blend(values: np.ndarray, alpha: np.ndarray, beta: np.ndarray | float = 0.0, gamma: float = GAMMA,
          linear: bool = True, matrix=None, signal=None) -> np.ndarray:
    """(h, w, C) uint8: display ``values`` (0..255, any float) blended as MPCDI says,
    ``P * alpha * (1 - beta) + beta`` in linear light, the output's ``gamma`` taken off before
    and put back after. ``alpha``, ``beta``: (h, w) or (h, w, C) linear, 0..1. ``linear=False``
    blends the encoded values instead (what tools that do not linearize do: for comparison).
    The output's colour (``warp/colour.py``): ``matrix`` (3x3) maps the content's linear light
    before the blend; ``signal`` (a function of (h, w, 3) 0..1 values) maps the encoded signal last."""
    a = np.asarray(alpha, dtype=np.float64)
    b = np.asarray(beta, dtype=np.float64)
    a = a[..., None] if a.ndim == 2 else a
    b = b[..., None] if b.ndim == 2 else b
    if not linear:
        v = np.asarray(values, dtype=np.float64) / 255.0
        return np.clip(np.round(255.0 * (v * a * (1 - b) + b)), 0, 255).astype(np.uint8)
    light = decode(values, gamma)
    if matrix is not None:
        light = np.clip(light @ np.asarray(matrix, dtype=np.float64).reshape(3, 3).T, 0.0, 1.0)
    light = light * a * (1 - b) + b
    if signal is None:
        return encode(light, gamma)
    coded = np.clip(light, 0.0, 1.0) ** (1.0 / gamma)
    return np.clip(np.round(255.0 * np.clip(signal(coded), 0.0, 1.0)), 0, 255).astype(np.uint8)


def map_values(image: np.ndarray, bit_depth: int = 8, gamma_embedded: float = 1.0) -> np.ndarray:
    """An alpha or beta map's image (integers up to ``2**bit_depth - 1``) as linear values in
    0..1: MPCDI's ``gammaEmbedded`` (the gamma the values were encoded with) taken off."""
    v = np.asarray(image, dtype=np.float64) / float(2 ** int(bit_depth) - 1)
    return np.clip(v, 0.0, 1.0) ** float(gamma_embedded)


def resample(values: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(h, w[, C]) a map of another size at an output's ``size`` (w, h), bilinear between the
    map's pixel centres (MPCDI allows a map of its own size: it covers the whole output)."""
    values = np.asarray(values, dtype=np.float64)
    w, h = size
    if values.shape[:2] == (h, w):
        return values
    flat = values if values.ndim == 3 else values[..., None]
    ys, xs = (np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w
    coords = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None]), axis=-1)
    out = sample(flat, coords)
    return out if values.ndim == 3 else out[..., 0]


def output(content: np.ndarray, coords: np.ndarray, alpha: np.ndarray, beta: np.ndarray | float = 0.0,
           gamma: float = GAMMA, linear: bool = True, matrix=None, signal=None) -> np.ndarray:
    """(h, w, C) uint8: an output's final picture: ``content`` sampled through its warp
    (``coords``, every output pixel's; ``upsample``), then blended and coloured (``blend``)."""
    return blend(sample(content, coords), alpha, beta, gamma, linear, matrix, signal)
