"""Portable float maps (PFM): the warp grids calibration tools write (MPCDI's, nDisplay's).

A PFM is a text header (``PF`` three channels or ``Pf`` one, the width and height, a scale whose
sign gives the byte order: negative little-endian) and then float32 rows, the bottom row first.
``read`` returns the rows top first, as every image here is held; ``write`` writes little-endian.
"""

from __future__ import annotations

import numpy as np

from multigpu.errors import InputError


def read(data: bytes, name: str) -> np.ndarray:
    """(h, w, C) float32, top row first, from a PFM file's bytes; ``name`` in the one-line error
    of a file that is not a PFM, is truncated or holds nothing but NaN."""
    fields, at = [], 0
    while len(fields) < 4:  # magic, width, height, scale: separated by any whitespace
        while at < len(data) and data[at:at + 1].isspace():
            at += 1
        end = at
        while end < len(data) and not data[end:end + 1].isspace():
            end += 1
        if end == at:
            raise InputError(f"{name}: not a PFM file (its header ends early)")
        fields.append(data[at:end])
        at = end
    at += 1  # the single whitespace byte before the pixels
    magic = fields[0]
    if magic not in (b"PF", b"Pf"):
        raise InputError(f"{name}: not a PFM file (it starts with {magic[:8]!r}, not PF or Pf)")
    try:
        w, h, scale = int(fields[1]), int(fields[2]), float(fields[3])
    except ValueError:
        raise InputError(f"{name}: a PFM header of another kind ({b' '.join(fields[1:]).decode(errors='replace')})") \
            from None
    if w < 1 or h < 1 or scale == 0 or not np.isfinite(scale):
        raise InputError(f"{name}: a PFM of {w} x {h} with scale {scale}: not a valid size and byte order")
    channels = 3 if magic == b"PF" else 1
    need = w * h * channels * 4
    if len(data) - at < need:
        raise InputError(f"{name}: a truncated PFM: {w} x {h} x {channels} floats need {need} bytes, "
                         f"it holds {len(data) - at}")
    values = np.frombuffer(data, dtype="<f4" if scale < 0 else ">f4", count=w * h * channels, offset=at)
    img = values.reshape(h, w, channels)[::-1].astype(np.float32)
    if not np.isfinite(img).any():
        raise InputError(f"{name}: every value of the PFM is NaN or infinite")
    return img


def write(img: np.ndarray) -> bytes:
    """A PFM file's bytes (little-endian) of ``img`` (h, w, 1 or 3), top row first."""
    img = np.asarray(img, dtype=np.float32)
    img = img[..., None] if img.ndim == 2 else img
    if img.shape[2] not in (1, 3):
        raise ValueError(f"a PFM holds 1 or 3 channels, got {img.shape[2]}")
    h, w, c = img.shape
    head = f"{'PF' if c == 3 else 'Pf'}\n{w} {h}\n-1.0\n".encode()
    return head + np.ascontiguousarray(img[::-1]).astype("<f4").tobytes()
