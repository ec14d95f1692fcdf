"""The cost model's least-squares fit (``strategies/cost.py``) in one compiled call.

``time = a*triangles + b*pixels + c`` over the last frames' per-rank samples: the normal
equations of the column-scaled features formed in one pass, solved by cofactors (at most 3x3),
and terms dropped, weakest failing first, until every kept one is positive, material (a share of
the predicted time of at least ``min_share``) and determined (relative standard error at most
``max_rel_se``). The numpy version this replaces made ~100 small numpy calls per frame.

Plain loops, no numpy calls: run uncompiled (``fit_terms.py_func``) it is its own reference,
the same operations in the same order, so the compiled and uncompiled strategies fit the same
coefficients bit for bit. A singular system returns status 0 and the caller solves it with
numpy's pseudo-inverse instead.
"""

from __future__ import annotations

import math

import numpy as np

from multigpu.core.jit import compile_all


def _solve(gram, rhs, use, m, inv, bs):
    """``inv`` = the inverse of ``gram[use][:, use]`` (m = 2 or 3, symmetric) by cofactors and
    ``bs`` = inv @ rhs[use]. False when the determinant is zero or not finite."""
    if m == 2:
        a, b, d = gram[use[0], use[0]], gram[use[0], use[1]], gram[use[1], use[1]]
        det = a * d - b * b
        if det == 0.0 or not math.isfinite(det):
            return False
        inv[0, 0], inv[0, 1], inv[1, 0], inv[1, 1] = d / det, -b / det, -b / det, a / det
    else:
        g = gram  # use is (0, 1, 2)
        c00 = g[1, 1] * g[2, 2] - g[1, 2] * g[2, 1]
        c01 = g[1, 2] * g[2, 0] - g[1, 0] * g[2, 2]
        c02 = g[1, 0] * g[2, 1] - g[1, 1] * g[2, 0]
        det = g[0, 0] * c00 + g[0, 1] * c01 + g[0, 2] * c02
        if det == 0.0 or not math.isfinite(det):
            return False
        inv[0, 0], inv[1, 0], inv[2, 0] = c00 / det, c01 / det, c02 / det
        inv[0, 1] = (g[0, 2] * g[2, 1] - g[0, 1] * g[2, 2]) / det
        inv[1, 1] = (g[0, 0] * g[2, 2] - g[0, 2] * g[2, 0]) / det
        inv[2, 1] = (g[0, 1] * g[2, 0] - g[0, 0] * g[2, 1]) / det
        inv[0, 2] = (g[0, 1] * g[1, 2] - g[0, 2] * g[1, 1]) / det
        inv[1, 2] = (g[0, 2] * g[1, 0] - g[0, 0] * g[1, 2]) / det
        inv[2, 2] = (g[0, 0] * g[1, 1] - g[0, 1] * g[1, 0]) / det
    for i in range(m):
        s = 0.0
        for j in range(m):
            s += inv[i, j] * rhs[use[j]]
        bs[i] = s
    return True


def _normal(data, scale, gram, rhs, mean):
    """The normal equations of ``data``'s column-scaled features (triangles, pixels, 1) in one
    pass into ``scale`` (largest magnitude per column), ``gram`` and ``rhs``, and the unscaled
    column means into ``mean``; returns y . y."""
    n = data.shape[0]
    for j in range(2):
        m = 0.0
        for i in range(n):
            m = max(m, abs(data[i, j]))
        scale[j] = max(m, 1e-300)
    scale[2] = 1.0
    yy = 0.0
    for i in range(n):
        x0, x1, y = data[i, 0] / scale[0], data[i, 1] / scale[1], data[i, 2]
        gram[0, 0] += x0 * x0
        gram[0, 1] += x0 * x1
        gram[0, 2] += x0
        gram[1, 1] += x1 * x1
        gram[1, 2] += x1
        gram[2, 2] += 1.0
        rhs[0] += x0 * y
        rhs[1] += x1 * y
        rhs[2] += y
        yy += y * y
        mean[0] += data[i, 0]
        mean[1] += data[i, 1]
    gram[1, 0], gram[2, 0], gram[2, 1] = gram[0, 1], gram[0, 2], gram[1, 2]
    mean[0], mean[1], mean[2] = mean[0] / n, mean[1] / n, 1.0
    return yy


def fit_terms(data, min_share, max_rel_se, out):
    """Fit ``data`` (R, 3): triangles, pixels, measured time per row. Writes ``out`` (10,):
    [beta_tri, beta_px, beta_const, share_tri, share_px, rel_tri, rel_px, ok_tri, ok_px,
    terms] (share/rel/ok NaN for a term not in the final fit; ``terms``: bit 0 triangles, bit 1
    pixels, the terms of the final fit). Returns 1, or 0 for a singular system (``out``
    unspecified)."""
    n = data.shape[0]
    scale, gram, rhs, mean = np.empty(3), np.zeros((3, 3)), np.zeros(3), np.zeros(3)
    yy = _normal(data, scale, gram, rhs, mean)
    terms = np.array([0, 1], dtype=np.int64)  # term ids still in the fit (0 triangles, 1 pixels)
    nt = 2
    use = np.empty(3, dtype=np.int64)
    inv = np.empty((3, 3))
    bs = np.empty(3)
    beta = np.empty(3)
    share, rel, ok = np.empty(2), np.empty(2), np.empty(2, dtype=np.bool_)
    while True:  # drop terms until every kept one is positive, material and stable
        m = nt + 1
        for i in range(nt):
            use[i] = terms[i]
        use[nt] = 2
        if not _solve(gram, rhs, use, m, inv, bs):
            return 0
        fit = 0.0  # bs @ rhs[use] and bs @ G @ bs
        quad = 0.0
        for i in range(m):
            fit += bs[i] * rhs[use[i]]
            row = 0.0
            for j in range(m):
                row += gram[use[i], use[j]] * bs[j]
            quad += bs[i] * row
        dof = max(n - m, 1)
        sigma2 = max(yy - 2 * fit + quad, 0.0) / dof
        pred = 0.0
        for i in range(m):
            beta[i] = bs[i] / scale[use[i]]
            pred += mean[use[i]] * beta[i]
        pred = max(pred, 1e-12)
        weakest = -1  # the failing term of the smallest share (the first of equals, as min())
        for i in range(nt):
            se = math.sqrt(max(sigma2 * inv[i, i], 0.0)) / scale[use[i]]
            rel[i] = se / beta[i] if beta[i] > 0 else np.inf
            share[i] = mean[use[i]] * beta[i] / pred
            ok[i] = beta[i] > 0 and share[i] >= min_share and rel[i] <= max_rel_se
            if not ok[i] and (weakest < 0 or share[i] < share[weakest]):
                weakest = i
        if weakest < 0 or nt == 1:
            break
        for i in range(weakest, nt - 1):  # drop the weakest failing term and refit
            terms[i] = terms[i + 1]
        nt -= 1
    for i in range(10):
        out[i] = np.nan
    out[0], out[1], out[9] = 0.0, 0.0, 0.0
    for i in range(nt):
        t = terms[i]
        out[t] = beta[i]
        out[3 + t], out[5 + t], out[7 + t] = share[i], rel[i], 1.0 if ok[i] else 0.0
        out[9] += 1 << t
    out[2] = beta[nt]
    return 1


compile_all(globals(), ("_solve", "_normal", "fit_terms"))
