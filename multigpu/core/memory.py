"""Process-wide allocator setting for the per-frame path.

Each frame allocates the same few MB-sized numpy temporaries (rects, spans, index arrays).
glibc serves blocks above its mmap threshold with fresh ``mmap`` calls and returns them on
free, so every frame pays the page faults of touching new memory again: at 10^5 objects that
doubled the balancer's time here (``multigpu bench balance`` prints both). Raising the mmap
and trim thresholds keeps such blocks in the heap, where they are reused warm. The price is
that a big setup (scene build, GL upload) leaves its freed temporaries in the heap too:
``release_heap`` hands them back once, after setup, before the first frame.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
# glibc caps the mmap threshold at HEAP_MAX_SIZE / 2 (32 MiB on 64-bit systems)
_MMAP_THRESHOLD = 32 << 20
_TRIM_THRESHOLD = 256 << 20

_applied: bool | None = None


def _libc():
    return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")


def keep_heap() -> bool:
    """Keep large temporaries in the heap (glibc only; elsewhere a no-op). Returns whether the
    setting is active. Idempotent. ``MULTIGPU_MALLOC=default`` leaves glibc's defaults (for
    comparison)."""
    global _applied
    if _applied is None:
        if os.environ.get("MULTIGPU_MALLOC", "keep") == "default":
            _applied = False
            return _applied
        try:
            mallopt = _libc().mallopt
        except (OSError, AttributeError):  # not glibc (macOS, musl without mallopt)
            _applied = False
        else:
            mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
            _applied = bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)) and bool(
                mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))
    return _applied


def release_heap() -> bool:
    """Return the heap's free memory to the system (glibc ``malloc_trim``; elsewhere a no-op).
    Called once after setup: the scene build's and the GL upload's freed temporaries would
    otherwise stay resident under the raised trim threshold. Returns whether anything went."""
    try:
        trim = _libc().malloc_trim
    except (OSError, AttributeError):  # not glibc
        return False
    trim.argtypes = [ctypes.c_size_t]
    return bool(trim(0))
