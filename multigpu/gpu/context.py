"""A rank's GL context: headless EGL on the device its place on the host picks, and llvmpipe's
rasterizer threads chosen before it is made."""

from __future__ import annotations

import os
import re

from multigpu.errors import InputError

EGL_HELP = ("EGL headless OpenGL is not available: install Mesa's EGL and GL drivers "
            "(Debian/Ubuntu: sudo apt install libegl1 libgl1-mesa-dri) or an NVIDIA driver with EGL")


class EglUnavailable(RuntimeError):
    """No headless EGL context could be made on this machine."""


def raster_threads(host_ranks: int) -> str:
    """Choose llvmpipe's rasterizer threads for a rank (``LP_NUM_THREADS``, unless the user set
    it; call before the first GL context) and return the value in effect.

    One thread when this host has a core to spare for it beside its ranks: the raster work
    overlaps the rank's own. None (0: the rank rasterizes on its own thread) when the ranks
    already fill the cores: a thread per rank then only competes for them, and its queued
    scenes cost memory. Measured at 4.28 M triangles on 4 ranks of 2 cores (docs/BENCHMARKS.md):
    0 threads, 4 % less CPU and wall time, ~100 MiB less per rank. The value never changes a
    pixel. A real GPU ignores it."""
    if "LP_NUM_THREADS" not in os.environ:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        os.environ["LP_NUM_THREADS"] = "1" if host_ranks < cores else "0"
    return os.environ["LP_NUM_THREADS"]


def create_context(device: int | None = None, local_rank: int = 0, host_ranks: int = 1):
    """A standalone EGL context, and the device index it is on.

    ``device`` picks an EGL device explicitly (``--device``); by default a rank takes
    ``local_rank`` modulo the machine's device count, so the ranks of one node spread over its
    GPUs. glcontext selects the device (``device_index``; its ``GLCONTEXT_DEVICE_INDEX``
    variable overrides both) and reports the device count when an index is out of range,
    which is all the counting needed. ``host_ranks``: the ranks on this host (``raster_threads``)."""
    raster_threads(host_ranks)
    import moderngl

    index = local_rank if device is None else device

    def make(i: int):
        return moderngl.create_standalone_context(backend="egl", require=430, device_index=i)

    try:
        return make(index), index
    except Exception as exc:
        found = re.search(r"found (\d+) devices", str(exc))
        if found and int(found.group(1)) > 0:
            count = int(found.group(1))
            if device is not None:
                raise InputError.of("device", f"{device}: this machine has {count} EGL device(s) "
                                              f"(0..{count - 1})") from None
            try:
                return make(index % count), index % count
            except Exception as again:
                exc = again
        why = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise EglUnavailable(f"{EGL_HELP} ({exc.__class__.__name__}: {why})") from None
