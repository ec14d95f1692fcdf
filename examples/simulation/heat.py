"""A small simulation that streams its steps to the wall through ADIOS2: heat spreading over a
plate from a source that circles it (the explicit 2-D heat equation, numpy), shown as a surface
whose height and colour are the temperature.

    python examples/simulation/heat.py                 # a live stream: SST, the contact file heat.sst
    python examples/simulation/heat.py --file heat.bp  # recorded to a BP5 file (the wall may follow it)

and on the wall (docs/USAGE.md, "A running simulation"):

    launch/walkthrough --model adios2:heat --color-by temperature --range 0,1 --path-kind orbit

Each step holds ``points`` (N*N, 3), ``quad`` (cells, 4) point indices, the ``temperature`` per
point, the ``source`` distance per cell, the step's ``time`` and when it was ``written``: what
``multigpu/scene/stream_mesh.py`` reads. The writer never waits for a reader (SST's queue drops
the oldest step when the wall is slow).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def plate(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) grids over [0, 1]^2 and the (cells, 4) quads of an ``n`` x ``n`` grid of points."""
    x, y = np.meshgrid(np.linspace(0.0, 1.0, n), np.linspace(0.0, 1.0, n))
    idx = np.arange(n * n).reshape(n, n)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    return np.stack([x, y]), quads.astype(np.int64)


def advance(u: np.ndarray, xy: np.ndarray, t: float, dt: float, sub: int = 20) -> np.ndarray:
    """``u`` after ``sub`` explicit steps of the heat equation (stable: alpha * dt / h^2 < 1/4), a
    source circling the plate's centre heating it, the edges held cold."""
    n = u.shape[0]
    h2 = (1.0 / (n - 1)) ** 2
    alpha = 0.2 * h2 / (dt / sub)
    for s in range(sub):
        ts = t + dt * s / sub
        cx, cy = 0.5 + 0.3 * np.cos(2 * np.pi * 0.25 * ts), 0.5 + 0.3 * np.sin(2 * np.pi * 0.25 * ts)
        source = np.exp(-((xy[0] - cx) ** 2 + (xy[1] - cy) ** 2) / 0.004)
        lap = np.zeros_like(u)
        lap[1:-1, 1:-1] = u[2:, 1:-1] + u[:-2, 1:-1] + u[1:-1, 2:] + u[1:-1, :-2] - 4 * u[1:-1, 1:-1]
        u = u + alpha * (dt / sub) * lap / h2 + (dt / sub) * 4.0 * source * (1.0 - u)
        u[0, :] = u[-1, :] = u[:, 0] = u[:, -1] = 0.0
    return u


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--name", default="heat", help="the SST stream's name (its contact file: NAME.sst)")
    p.add_argument("--file", help="write a BP5 file (NAME.bp) instead of a live SST stream")
    p.add_argument("--steps", type=int, default=200, help="steps to write (default 200)")
    p.add_argument("--size", type=int, default=96, help="grid points a side (default 96)")
    p.add_argument("--every", type=float, default=0.1, help="seconds between steps (default 0.1)")
    a = p.parse_args(argv)
    from adios2 import Adios, Stream

    io = Adios().declare_io("heat")
    if a.file:
        io.set_engine("BP5")
    else:
        io.set_engine("SST")
        io.set_parameters({"RendezvousReaderCount": "0", "QueueLimit": "2", "QueueFullPolicy": "Discard",
                           "DataTransport": "WAN"})
    xy, quads = plate(a.size)
    u = np.zeros((a.size, a.size))
    dt = 0.05
    centres = xy.reshape(2, -1)[:, quads].mean(axis=2)  # (2, cells)
    with Stream(io, a.file or a.name, "w") as out:
        for k in range(a.steps):
            t = k * dt
            u = advance(u, xy, t, dt)
            points = np.c_[xy[0].ravel(), xy[1].ravel(), 0.25 * u.ravel()]
            cx, cy = 0.5 + 0.3 * np.cos(2 * np.pi * 0.25 * t), 0.5 + 0.3 * np.sin(2 * np.pi * 0.25 * t)
            out.begin_step()
            out.write("points", points, points.shape, [0, 0], points.shape)
            out.write("quad", quads, quads.shape, [0, 0], quads.shape)
            temp = np.ascontiguousarray(u.ravel())
            out.write("temperature", temp, temp.shape, [0], temp.shape)
            dist = np.hypot(centres[0] - cx, centres[1] - cy)
            out.write("source", dist, dist.shape, [0], dist.shape)
            out.write("time", np.array([t]))
            out.write("written", np.array([time.time()]))  # the wall measures its delay from it
            out.end_step()
            if a.every > 0:
                time.sleep(a.every)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
