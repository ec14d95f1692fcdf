"""What the benchmarks share: a median timer and synthetic plant-like objects (boxes, spheres and
triangle counts) for the balancer's and the bounds' benchmarks at any object count."""

from __future__ import annotations

import time

import numpy as np


def median_ms(fn, repeat: int) -> float:
    fn()  # warm up (first-touch page faults, caches)
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times) * 1e3)


def synthetic_objects(n: int, seed: int = 0):
    """Clustered boxes in a 200 x 120 x 30 plant-sized volume, heavy-tailed triangle counts."""
    rng = np.random.default_rng(seed)
    halls = np.array([[45, 35, 8], [140, 80, 8], [40, 92, 8]])
    dense = rng.random(n) < 0.8
    c = np.where(dense[:, None], halls[rng.integers(0, 3, n)] + rng.normal(0, [12, 8, 5], (n, 3)),
                 rng.random((n, 3)) * [200, 120, 30])
    h = rng.exponential(0.6, (n, 3)) + 0.05
    tris = (rng.pareto(1.1, n) * 20 + 12).astype(np.int64)
    return c - h, c + h, c, np.linalg.norm(h, axis=1), tris
