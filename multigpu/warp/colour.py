"""A projector output's colour: a 3x3 matrix in linear light and a lookup table on its signal
(applied by ``core.warpblend.blend``).

Projectors of one wall never show one colour alike; calibration tools measure each and give a
correction per output, as a 3x3 matrix (matching primaries, in linear light: applied to the
content before the blend) and a 1D or 3D lookup table in the `.cube` format (Adobe/Resolve's,
what colour tools export: applied last, to the signal the projector gets, as a projector's own
LUT does). ``read_matrix`` checks a matrix; ``read_cube`` reads a table (``LUT_1D_SIZE`` or
``LUT_3D_SIZE``, ``DOMAIN_MIN`` and ``DOMAIN_MAX``, red changing fastest), refusing a bad file in
one line; ``apply_lut`` samples it linearly (1D: per channel; 3D: trilinear). Pure numpy.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from multigpu.errors import InputError

#: the largest table a file may declare (3D: this many samples a side)
MOST_3D, MOST_1D = 256, 65536


@dataclass(frozen=True)
class Lut:
    """A lookup table: (N, 3) for 1D, (N, N, N, 3) indexed [blue, green, red] for 3D, over the
    input domain ``lo``..``hi`` (3,)."""

    table: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    @property
    def dims(self) -> int:
        return 1 if self.table.ndim == 2 else 3


def read_cube(path: Path, field: str = "wall") -> Lut:
    """A ``.cube`` file, or an ``InputError`` naming the file and what is wrong with it."""
    path = Path(path)
    where = f"{path}"
    try:
        text = path.read_text(encoding="utf-8", errors="strict")
    except FileNotFoundError:
        raise InputError.of(field, f"{where}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError.of(field, f"{where}: cannot read it as a .cube LUT ({exc.__class__.__name__})") from None
    size, dims, lo, hi, rows = None, 0, [0.0] * 3, [1.0] * 3, []
    for n, line in enumerate(text.splitlines(), 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        key = words[0].upper()
        try:
            if key in ("LUT_1D_SIZE", "LUT_3D_SIZE"):
                dims, size = (1 if key == "LUT_1D_SIZE" else 3), int(words[1])
            elif key in ("DOMAIN_MIN", "DOMAIN_MAX"):
                v = [float(w) for w in words[1:4]]
                if len(v) != 3:
                    raise ValueError
                lo, hi = (v, hi) if key == "DOMAIN_MIN" else (lo, v)
            elif key in ("TITLE", "LUT_1D_INPUT_RANGE", "LUT_3D_INPUT_RANGE"):
                continue
            else:
                v = [float(w) for w in words]
                if len(v) != 3:
                    raise ValueError
                rows.append(v)
        except (ValueError, IndexError):
            raise InputError.of(field, f"{where}: line {n} is not a .cube line: '{line.strip()[:60]}'") from None
    if size is None:
        raise InputError.of(field, f"{where}: no LUT_1D_SIZE or LUT_3D_SIZE: not a .cube LUT")
    most = MOST_1D if dims == 1 else MOST_3D
    if not 2 <= size <= most:
        raise InputError.of(field, f"{where}: a {dims}D size of {size} (2..{most})")
    want = size if dims == 1 else size ** 3
    if len(rows) != want:
        raise InputError.of(field, f"{where}: {len(rows)} entries for a {dims}D LUT of size {size} ({want} wanted)")
    table = np.asarray(rows, dtype=np.float64)
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    if not (np.isfinite(table).all() and np.isfinite(lo).all() and np.isfinite(hi).all()) or (hi <= lo).any():
        raise InputError.of(field, f"{where}: non-finite entries, or a domain whose max is not above its min")
    return Lut(table if dims == 1 else table.reshape(size, size, size, 3), lo, hi)


def apply_lut(values: np.ndarray, lut: Lut) -> np.ndarray:
    """(..., 3) values (0..1 signal) through ``lut``, linearly between its samples (clamped to its
    domain)."""
    v = np.asarray(values, dtype=np.float64)
    n = lut.table.shape[0]
    x = np.clip((v - lut.lo) / (lut.hi - lut.lo), 0.0, 1.0) * (n - 1)
    i0 = np.minimum(x.astype(np.int64), n - 2)
    t = x - i0
    if lut.dims == 1:
        out = np.empty_like(v)
        for c in range(3):  # channels
            col = lut.table[:, c]
            out[..., c] = col[i0[..., c]] * (1 - t[..., c]) + col[i0[..., c] + 1] * t[..., c]
        return out
    r0, g0, b0 = i0[..., 0], i0[..., 1], i0[..., 2]
    tr, tg, tb = t[..., 0:1], t[..., 1:2], t[..., 2:3]
    T = lut.table
    out = 0.0
    for db, wb in ((0, 1 - tb), (1, tb)):  # the cube's eight corners
        for dg, wg in ((0, 1 - tg), (1, tg)):
            for dr, wr in ((0, 1 - tr), (1, tr)):
                out = out + T[b0 + db, g0 + dg, r0 + dr] * (wb * wg * wr)
    return out


def read_matrix(value, where: str) -> np.ndarray:
    """A 3x3 colour matrix (rows: each output channel's weights of red, green, blue), finite, its
    rows' sums in 0..4, or one line saying what is wrong."""
    try:
        m = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        m = np.zeros(0)
    if m.shape != (3, 3) or not np.isfinite(m).all():
        raise InputError(f"{where}: a colour matrix is 3 rows of 3 finite numbers, got {value!r}"[:200])
    if (m.sum(axis=1) < 0).any() or (m.sum(axis=1) > 4).any():
        raise InputError(f"{where}: a colour matrix's rows must sum to 0..4, got {m.sum(axis=1).tolist()}")
    return m
