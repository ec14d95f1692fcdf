"""numba where installed: ``jit`` compiles a function in nopython mode with an on-disk cache
(``cache=True``: compiled once per machine, loaded afterwards); without numba it is None and
the numpy references run."""

from __future__ import annotations

try:
    import numba

    jit = numba.njit(cache=True, nogil=True, error_model="numpy")  # IEEE division: no per-division checks
except ImportError:  # the numpy references run instead
    numba = None
    jit = None


def compile_all(namespace: dict, names: tuple[str, ...]) -> None:
    """Replace the plain functions ``names`` of a module by their compiled versions (in place,
    so compiled callers find compiled callees); a no-op without numba."""
    if jit is not None:
        for name in names:
            namespace[name] = jit(namespace[name])
