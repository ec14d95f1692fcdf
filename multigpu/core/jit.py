"""numba where installed: ``jit`` compiles a function in nopython mode with an on-disk cache
(``cache=True``: compiled once per machine, loaded afterwards); without numba it is None and
the numpy references run. ``entry`` gives a kernel's compiled entry point for one fixed set of
argument types, for per-frame calls whose arguments the caller owns."""

from __future__ import annotations

from typing import Callable

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


def entry(kernel, args: tuple) -> Callable:
    """The compiled entry point of ``kernel`` (a jitted function) for the types of ``args``
    (compiled, or loaded from numba's cache, now): called with arguments of exactly those types
    it skips numba's per-call type dispatch, which costs 10-20 us of CPU per call once
    rendering has flushed the caches (ad hoc cold timing in docs/BENCHMARKS.md). Only for
    arguments the caller owns: the same dtypes, dimensions and contiguity every call (the entry
    point does not check them all). Without numba, or where numba keeps no entry point, the
    kernel itself."""
    dispatcher = getattr(kernel, "py_func", None) and kernel
    if dispatcher is None or numba is None:
        return kernel
    sig = tuple(numba.typeof(a) for a in args)
    if sig not in dispatcher.overloads:
        dispatcher.compile(sig)
    got = getattr(dispatcher.overloads.get(sig), "entry_point", None)
    return got if callable(got) else kernel


def available() -> bool:
    """Whether numba is installed (the kernels run compiled)."""
    return numba is not None


def use(compiled: bool | None) -> bool:
    """Whether to run a kernel: ``compiled`` None means where numba is installed; True insists."""
    if compiled and not available():
        raise ValueError("compiled=True needs numba (pip install numba)")
    return available() if compiled is None else bool(compiled)

