"""Octahedral normal codes compiled (core/octahedral_kernel.py) against the numpy reference
(core/octahedral.encode_reference): the same 32 bits for every normal, random and unit ones, zero,
signed zeros, subnormal, huge, infinite and NaN coordinates."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from multigpu.core import jit
from multigpu.core.octahedral import encode, encode_reference, pack

pytestmark = pytest.mark.skipif(not jit.available(), reason="numba is not installed (pip install numba)")


def same(normals):
    with np.errstate(all="ignore"):
        want = encode_reference(normals)
        got = encode(normals, compiled=True)
    assert got.dtype == want.dtype == np.uint32 and got.shape == want.shape
    assert np.array_equal(got, want), f"differs at {np.argwhere(got != want)[:5].ravel().tolist()}"


@settings(max_examples=300, deadline=None)
@given(hnp.arrays(np.float32, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=40).map(
    lambda s: (s[0], 3)), elements=st.floats(width=32, allow_nan=True, allow_infinity=True)))
def test_compiled_codes_equal_the_reference_for_any_float32_normals(normals):
    same(normals)


def test_unit_normals_the_fold_ties_and_extremes_code_alike():
    rng = np.random.default_rng(3)
    unit = rng.normal(size=(20000, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    specials = np.array([[0, 0, 0], [-0.0, -0.0, -0.0], [0, 0, -1], [0, -0.0, -1], [1, 0, 0], [-1, 0, 0],
                         [1e-45, 0, 0], [1e308, 1e308, -1e308], [np.inf, 0, 0], [np.nan, 0.5, 0.2],
                         [0.25, 0.25, -0.5], [1 / 3, 1 / 3, -1 / 3], [0.5, 0.5, 0]], dtype=np.float64)
    with np.errstate(over="ignore"):  # (1e308 as float32: inf, as meant)
        narrow = specials.astype(np.float32)
    for normals in (unit, unit.astype(np.float32), specials, narrow):
        same(normals)
    assert encode(np.zeros((1, 3)), compiled=True)[0] == encode_reference(np.array([[0.0, 0.0, 1.0]]))[0]  # +z


@settings(max_examples=200, deadline=None)
@given(hnp.arrays(np.float32, st.integers(0, 40).map(lambda n: (n, 6)),
                  elements=st.floats(width=32, allow_nan=True, allow_infinity=True)))
def test_compiled_vertices_pack_as_the_reference_does(vertices):
    """``pack``: the positions' float32 bits as they are (NaN payloads too) and the normals' codes."""
    with np.errstate(all="ignore"):
        want = pack(vertices, compiled=False)
        got = pack(vertices, compiled=True)
    assert got.dtype == want.dtype == np.uint32 and got.shape == want.shape == (len(vertices), 4)
    assert np.array_equal(got, want)
    assert np.array_equal(got[:, :3], np.ascontiguousarray(vertices[:, :3]).view(np.uint32))
