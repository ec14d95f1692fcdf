"""Pixels on the wire between PCs: a message's packed bytes framed, compressed by a well-kept
codec, and checked when they arrive (DESIGN.md, "The wire").

A message is a 24-byte header and a payload. The header says the codec, the low colour bits a lossy
frame dropped, and the raw and payload lengths; the payload is the packed bytes as that codec
leaves them. A payload no smaller than the raw bytes, or raw bytes below the codec's
``least`` bytes, go raw (codec ``none``): compressing them saves nothing. Both codecs
carry a checksum of the content (zstd's and LZ4 frame's) and a raw payload carries its CRC-32
in the header, so a corrupt or short message is found, named and never composed. The receiver
posts ``bound(raw)`` bytes, the largest message for ``raw`` packed bytes, and checks that the
bytes that arrived are what the header says.

The packed bytes are laid out for the codec by ``rank/composite.py`` on a compressed link: every
part's colour first, then the depth of every part as four byte planes (lowest bytes of every
pixel, then the next...). Depth's high bytes vary slowly and its background is one value, so the
planes compress 10-20x with zstd where the interleaved floats compress 1-8x (measured: ``multigpu
bench network``, its codec table, on the plant and the textured pump).

Chosen by that measurement on rendered frames (full-HD and 4K, colour, and sort-last colour and
depth): zstd level 1 leaves 1.5-3x fewer bytes than LZ4 at about the same speed on this machine,
level 3 a few per cent fewer at half the speed, and blosc2's shuffle did no better than these
planes with zstd (a one-off check, not in the benchmark). Pure: no MPI, no GL.
"""

from __future__ import annotations

import struct
import threading
import zlib
from dataclasses import dataclass

import numpy as np

#: codec names on the command line and in the wall file, by header id
CODECS = ("none", "lz4", "zstd")
#: magic, codec id, dropped colour bits, two spare bytes, a raw payload's CRC-32 (0 for a compressed
#: one: its codec checks its own), four spare bytes, raw length, payload length
HEADER = struct.Struct("<4sBBxxIxxxxQQ")
MAGIC = b"MGW2"
HEADER_BYTES = HEADER.size  # 32: the payload stays 8-byte aligned
#: raw bytes below which a message goes raw: one page. Not measured: such a piece takes gigabit
#: about 35 us, the order of two codec calls' fixed cost, so compressing it saves next to nothing
#: (Equalizer found small tiles not worth compressing)
LEAST = 4096


class WireError(ValueError):
    """A message that is not what its header says: corrupt, short, or of an unknown codec."""


@dataclass(frozen=True)
class Codec:
    """How one link's messages travel: the codec (``none``, ``lz4``, ``zstd``), its level, and the raw
    bytes below which a message goes raw."""

    name: str = "zstd"
    level: int = 1
    least: int | None = None  # None: ``LEAST``

    def __post_init__(self):
        if self.name not in CODECS:
            raise ValueError(f"unknown codec '{self.name}' (use {', '.join(CODECS)})")

    @property
    def compresses(self) -> bool:
        return self.name != "none"


RAW = Codec("none")


def parse(text: str) -> Codec:
    """``none``, ``lz4``, ``zstd`` or ``zstd:LEVEL`` (1..19) as a Codec; ValueError naming what is wrong."""
    name, _, level = text.partition(":")
    if name not in CODECS:
        raise ValueError(f"unknown codec '{name}' (use {', '.join(CODECS)}, or zstd:LEVEL)")
    if not level:
        return Codec(name)
    if name != "zstd" or not level.isdigit() or not 1 <= int(level) <= 19:
        raise ValueError(f"'{text}': only zstd takes a level, 1..19")
    return Codec(name, int(level))


#: each thread's zstd contexts (a context is not thread-safe: ranks as threads of one process each
#: have theirs, tests/threadcomm.py)
_MINE = threading.local()


def _zstd(level: int):
    made = _MINE.__dict__.setdefault("zstd", {})
    if level not in made:
        import zstandard

        made[level] = zstandard.ZstdCompressor(level=level, write_checksum=True, write_content_size=True)
    return made[level]


def _unzstd():
    if not hasattr(_MINE, "unzstd"):
        import zstandard

        _MINE.unzstd = zstandard.ZstdDecompressor()
    return _MINE.unzstd


def _compress(codec: Codec, data: memoryview) -> bytes:
    if codec.name == "zstd":
        return _zstd(codec.level).compress(data)
    import lz4.frame

    return lz4.frame.compress(data, compression_level=0, content_checksum=True, store_size=True)


def _decompress(codec_id: int, payload: memoryview, raw: int) -> bytes:
    name = CODECS[codec_id]
    try:
        if name == "zstd":
            return _unzstd().decompress(payload, max_output_size=raw)
        import lz4.frame

        return lz4.frame.decompress(payload)
    except Exception as exc:  # the libraries' own errors: zstd.ZstdError, RuntimeError (lz4)
        raise WireError(f"{name} payload does not decode ({exc})") from None


def _lz4_size(payload: np.ndarray) -> int | None:
    """The content size an LZ4 frame declares (None where it declares none or is no frame)."""
    import lz4.frame

    try:
        return lz4.frame.get_frame_info(memoryview(payload)).get("content_size") or None
    except Exception:  # noqa: BLE001 - the library's own error for a header that is no frame
        return None


def bound(raw: int) -> int:
    """The most bytes a message of ``raw`` packed bytes takes (a compressed payload never larger
    than the raw one is sent: the receiver's buffer)."""
    return HEADER_BYTES + raw


def encode(packed: np.ndarray, codec: Codec, colour: int = 0, bits: int = 0) -> np.ndarray:
    """The message for ``packed`` (uint8, contiguous): compressed by ``codec`` where that makes it
    smaller. ``bits``: low bits dropped from each of the first ``colour`` bytes (a lossy frame;
    ``packed`` is changed in place), 0..7."""
    raw = packed.nbytes
    if bits:
        packed[:colour] &= np.uint8((0xFF << bits) & 0xFF)
    payload = None
    if codec.compresses and raw >= (LEAST if codec.least is None else codec.least):
        payload = _compress(codec, memoryview(packed))
        if len(payload) >= raw:
            payload = None
    crc = 0
    if payload is None:
        out = np.empty(HEADER_BYTES + raw, dtype=np.uint8)
        out[HEADER_BYTES:] = packed
        cid, crc = 0, zlib.crc32(packed)
    else:
        out = np.empty(HEADER_BYTES + len(payload), dtype=np.uint8)
        out[HEADER_BYTES:] = np.frombuffer(payload, dtype=np.uint8)
        cid = CODECS.index(codec.name)
    out[:HEADER_BYTES] = np.frombuffer(HEADER.pack(MAGIC, cid, bits, crc, raw, out.nbytes - HEADER_BYTES), np.uint8)
    return out


def header(message: np.ndarray) -> tuple[int, int, int, int]:
    """(codec id, dropped bits, raw bytes, payload bytes) of a message; WireError where the
    header is not one."""
    cid, bits, _, raw, size = _head(message)
    return cid, bits, raw, size


def _head(message: np.ndarray) -> tuple[int, int, int, int, int]:
    if message.nbytes < HEADER_BYTES:
        raise WireError(f"a message of {message.nbytes} bytes is shorter than its header")
    magic, cid, bits, crc, raw, size = HEADER.unpack(message[:HEADER_BYTES].tobytes())
    if magic != MAGIC or cid >= len(CODECS) or bits > 7:
        raise WireError("the message's header is not multigpu's (corrupt)")
    return cid, bits, crc, raw, size


def decode(message: np.ndarray, raw: int, received: int | None = None) -> tuple[np.ndarray, int]:
    """The packed bytes of a message expected to hold ``raw`` of them, and the colour bits the
    sender dropped; WireError naming what is wrong where the message is corrupt or short.
    ``message`` may be a receive buffer longer than the message (``bound(raw)`` bytes): then
    ``received`` is how many bytes arrived (MPI's ``Get_count``), which must be what the header
    says, so that no byte of the buffer that nothing wrote is ever read."""
    if received is not None:
        message = message[:received]
    cid, bits, crc, got, size = _head(message)
    if got != raw:
        raise WireError(f"the message holds {got} bytes where {raw} were expected")
    if HEADER_BYTES + size > message.nbytes:
        raise WireError(f"the message is short: {message.nbytes - HEADER_BYTES} of {size} payload bytes")
    if received is not None and HEADER_BYTES + size != received:
        raise WireError(f"{received} bytes arrived where the header says {HEADER_BYTES + size}")
    payload = message[HEADER_BYTES:HEADER_BYTES + size]
    if cid == 0:
        if size != raw:
            raise WireError(f"a raw payload of {size} bytes where {raw} were expected")
        if zlib.crc32(payload) != crc:
            raise WireError("a raw payload whose checksum does not match (corrupt)")
        return payload, bits
    if CODECS[cid] == "lz4":  # a frame that claims another size is refused before it is decoded
        claimed = _lz4_size(payload)
        if claimed != raw:
            raise WireError(f"an lz4 frame that says {claimed} bytes where {raw} were expected")
    data = _decompress(cid, memoryview(payload), raw)
    if len(data) != raw:
        raise WireError(f"the payload decodes to {len(data)} bytes where {raw} were expected")
    return np.frombuffer(data, dtype=np.uint8), bits


#: what ``auto`` puts on a link between PCs (within one PC messages stay raw: memory is faster than
#: any codec there)
AUTO = Codec("zstd", 1)


def links(setting: str, hosts: list[str], me: int) -> dict[int, Codec]:
    """The codec of each rank whose messages with rank ``me`` travel compressed, by ``--compress``:
    ``auto`` (zstd to ranks on other hosts), ``none`` (no link), or one codec on every link.
    ``hosts``: every rank's host. Both ends of a link get the same codec."""
    if setting == "none":
        return {}
    if setting == "auto":
        return {r: AUTO for r, h in enumerate(hosts) if h != hosts[me]}
    codec = parse(setting)
    return {r: codec for r in range(len(hosts)) if r != me}


def describe(setting: str, hosts: list[str]) -> str:
    """What ``--compress`` chose for this job, as the run's header says it."""
    between = len(set(hosts)) > 1
    if setting == "none":
        return "none"
    if setting == "auto":
        return f"zstd:{AUTO.level} between PCs" if between else "none (one PC)"
    c = parse(setting)
    return f"{c.name}" + (f":{c.level}" if c.name == "zstd" else "") + " on every message"
