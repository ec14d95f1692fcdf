"""Draw commands compiled (``drawlist.DrawList.commands``): one pass over the buffer order turns
a rank's object mask into one ``(count, 1, first, 0, 0)`` command per run of visible objects,
where the reference makes a dozen numpy passes; ``_part_commands`` the same over an object's
parts that its region needs. The same commands (tests/test_kernel.py)."""

from __future__ import annotations

import numpy as np

from multigpu.core.jit import compile_all


def _commands(mask, order, offsets):
    n = order.shape[0]
    cmd = np.zeros(((n + 1) // 2 + 1, 5), dtype=np.uint32)  # at most one run per two objects, plus one
    r = 0
    start = -1
    for i in range(n + 1):
        vis = i < n and mask[order[i]]
        if vis and start < 0:
            start = i
        elif not vis and start >= 0:
            count = offsets[i] - offsets[start]
            if count > 0:  # runs of zero-triangle objects draw nothing
                cmd[r, 0], cmd[r, 1], cmd[r, 2] = count, 1, offsets[start]
                r += 1
            start = -1
    return cmd[:r].copy()


def _part_commands(mask, seen, part_obj, order, offsets):
    """``_commands`` over parts: a part is drawn where its object is in ``mask`` and the part is
    ``seen`` (its bounds reach the region); ``order``/``offsets``: the parts in buffer order."""
    n = order.shape[0]
    cmd = np.zeros(((n + 1) // 2 + 1, 5), dtype=np.uint32)
    r = 0
    start = -1
    for i in range(n + 1):
        vis = False
        if i < n:
            p = order[i]
            vis = mask[part_obj[p]] and seen[p]
        if vis and start < 0:
            start = i
        elif not vis and start >= 0:
            count = offsets[i] - offsets[start]
            if count > 0:
                cmd[r, 0], cmd[r, 1], cmd[r, 2] = count, 1, offsets[start]
                r += 1
            start = -1
    return cmd[:r].copy()


compile_all(globals(), ("_commands", "_part_commands"))
