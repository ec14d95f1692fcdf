"""Static bin patterns (Kerbl et al. 2017): which rank owns each B x B pixel bin. Pure numpy.

Bin (bx, by) counts from the lower left corner. With ``K`` ranks:

* ``scanline``: bin rows interleaved, ``by mod K`` (sort-middle's simplest pattern);
* ``diagonal``: each row's first rank offset by one, ``(bx + by) mod K`` (NVIDIA's, the
  paper's baseline; a checkerboard for K = 2);
* ``zcurve``: the bin's 2-D Morton code mod K;
* ``xshift``: X-shift+offset, row i shifted by ``floor(i (K+1) / k) mod K`` with
  ``k = floor(sqrt K)``;
* ``vandercorput``: row shifts from the base-2 Van der Corput sequence scaled by the next
  power of two >= K, shifts >= K skipped, repeating every K rows (the paper's best).
"""

from __future__ import annotations

import math

import numpy as np

PATTERNS = ("scanline", "diagonal", "zcurve", "xshift", "vandercorput")


def _morton2(x: np.ndarray, y: np.ndarray, bits: int = 16) -> np.ndarray:
    code = np.zeros(x.shape, dtype=np.int64)
    for b in range(bits):  # bits of the code, not bins
        code |= ((x >> b) & 1) << (2 * b)
        code |= ((y >> b) & 1) << (2 * b + 1)
    return code


def _van_der_corput_shifts(k: int) -> np.ndarray:
    """The first ``k`` row shifts of the Van der Corput pattern."""
    p = 1 << max(0, math.ceil(math.log2(k)))
    out, i = [], 0
    while len(out) < k:  # at most 2k terms
        v, f, n = 0.0, 0.5, i
        while n:
            v += f * (n & 1)
            n >>= 1
            f /= 2
        s = int(v * p)
        if s < k:
            out.append(s)
        i += 1
    return np.array(out, dtype=np.int64)


def owner(pattern: str, bx: np.ndarray, by: np.ndarray, ranks: int) -> np.ndarray:
    """Rank owning each bin (arrays of bin coordinates)."""
    bx, by, k = np.asarray(bx, np.int64), np.asarray(by, np.int64), int(ranks)
    if pattern == "scanline":
        return by % k
    if pattern == "diagonal":
        return (bx + by) % k
    if pattern == "zcurve":
        return _morton2(bx, by) % k
    if pattern == "xshift":
        rows = max(1, math.isqrt(k))
        return (bx + (by * (k + 1)) // rows) % k
    if pattern == "vandercorput":
        return (bx + _van_der_corput_shifts(k)[by % k]) % k
    raise ValueError(f"unknown bin pattern '{pattern}' (known: {', '.join(PATTERNS)})")


def bin_rects(size, bin_size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, 4) int64 pixel rects of every bin (edge bins clipped to the display), and their
    (bx, by) coordinates."""
    W, H = size
    nx, ny = -(-W // bin_size), -(-H // bin_size)
    by, bx = np.divmod(np.arange(nx * ny, dtype=np.int64), nx)
    x0, y0 = bx * bin_size, by * bin_size
    rects = np.stack([x0, y0, np.minimum(x0 + bin_size, W), np.minimum(y0 + bin_size, H)], axis=1)
    return rects, bx, by
