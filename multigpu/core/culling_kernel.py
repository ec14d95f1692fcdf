"""Sub-object culling compiled (``culling.PartCuller.seen``): one pass over the cut objects'
parts turns their projected rects into the parts a region needs, where the reference makes a
dozen numpy passes (pixel spans, the on-screen test, the overlap test, the scatter). The same
arithmetic in the same order, so the same parts (tests/test_culling.py)."""

from __future__ import annotations

from multigpu.core.jit import compile_all


def _seen(rt, W, H, x0, y0, x1, y1, rows, out):
    """``out[rows[s]]`` = part ``s``'s rect (``rt``: (4, S) normalized, NaN unseen) has a pixel
    span on the ``W`` x ``H`` canvas that touches the half-open region [x0, x1) x [y0, y1)."""
    for s in range(rows.shape[0]):
        a, b, c, d = rt[0, s], rt[1, s], rt[2, s], rt[3, s]
        hit = c >= 0.0 and a <= 1.0 and d >= 0.0 and b <= 1.0  # False for NaN
        if hit:
            sx0 = int(min(max(a * W, 0.0), W - 1.0))
            sy0 = int(min(max(b * H, 0.0), H - 1.0))
            sx1 = int(min(max(c * W, 0.0), W - 1.0))
            sy1 = int(min(max(d * H, 0.0), H - 1.0))
            hit = sx0 < x1 and sx1 >= x0 and sy0 < y1 and sy1 >= y0
        out[rows[s]] = hit


compile_all(globals(), ("_seen",))
