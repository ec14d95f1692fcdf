"""``adaptive``'s sums over a partition's T' masks compiled: per rank, the triangles it draws and
their corrected weights (its prediction); per object, the log errors of the ranks that drew it
and how many did (its correction). Numpy's ``vis @ x`` leaves the order of a float sum to BLAS
and converts the (K, N) mask to floats first; here one pass over the mask, the sums in index
order as the references in ``strategies/adaptive.py`` add them (cumulative sums), so the
corrections are the same bit for bit (tests/test_kernel.py)."""

from __future__ import annotations

from multigpu.core.jit import compile_all


def _rank_sums(vis, tris, weights, loads, weighed):
    """Per rank k: ``loads[k]`` the triangles (int64 ``tris``) of the objects it draws,
    ``weighed[k]`` their ``weights`` added in object order (the objects it does not draw add 0.0)."""
    k, n = vis.shape
    for r in range(k):
        total, acc = 0, 0.0
        for o in range(n):
            x = weights[o] if vis[r, o] else 0.0
            acc = x if o == 0 else acc + x
            if vis[r, o]:
                total += tris[o]
        loads[r], weighed[r] = total, acc


def _object_sums(vis, log_s, sums, count):
    """Per object o: ``sums[o]`` the ``log_s`` of the ranks that draw it added in rank order
    (the others add 0.0), ``count[o]`` how many draw it."""
    k, n = vis.shape
    for o in range(n):
        sums[o] = log_s[0] if vis[0, o] else 0.0
        count[o] = 1 if vis[0, o] else 0
    for r in range(1, k):
        for o in range(n):
            if vis[r, o]:
                sums[o] += log_s[r]
                count[o] += 1
            else:
                sums[o] += 0.0


compile_all(globals(), ("_rank_sums", "_object_sums"))
