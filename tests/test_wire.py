"""Pixels on the wire (``core/wire.py``, ``rank/composite.py``'s planar packing): every message
decodes to what was packed, a corrupt or short one is refused with its reason, both ends of a
link agree on its codec. One process, no MPI, no GL."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from multigpu.core import wire
from multigpu.core.work import Piece
from multigpu.rank.composite import CorruptPiece, Posted, Sent, _pack_planar, _unpack_planar


def _image(h=120, w=160, seed=0) -> np.ndarray:
    """A frame like a render: a flat background, a shaded disc, some noise on it."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:h, :w]
    img = np.full((h, w, 3), (30, 30, 40), np.uint8)
    disc = (x - w / 2) ** 2 + (y - h / 2) ** 2 < (min(h, w) / 3) ** 2
    shade = (x * 255 // w).astype(np.uint8)
    img[disc] = np.stack([shade, 255 - shade, shade // 2], axis=-1)[disc]
    img[disc] ^= rng.integers(0, 4, size=(int(disc.sum()), 3), dtype=np.uint8)
    return img


@pytest.mark.parametrize("codec", ["lz4", "zstd", "zstd:3"])
def test_a_frame_travels_compressed_and_comes_back_exact(codec):
    packed = _image().reshape(-1).copy()
    msg = wire.encode(packed.copy(), wire.parse(codec))
    assert msg.nbytes < packed.nbytes / 2  # a render's background compresses
    got, bits = wire.decode(msg, packed.nbytes)
    assert bits == 0 and (got == packed).all()
    buf = np.zeros(wire.bound(packed.nbytes), np.uint8)  # as received: a buffer of the bound, longer
    buf[:msg.nbytes] = msg
    assert (wire.decode(buf, packed.nbytes)[0] == packed).all()


def test_small_and_incompressible_messages_go_raw():
    small = np.arange(100, dtype=np.uint8)
    msg = wire.encode(small.copy(), wire.Codec("zstd"))
    assert wire.header(msg)[0] == 0 and msg.nbytes == wire.HEADER_BYTES + 100
    noise = np.random.default_rng(1).integers(0, 256, 50_000, dtype=np.uint8)
    msg = wire.encode(noise.copy(), wire.Codec("zstd"))
    assert wire.header(msg)[0] == 0 and msg.nbytes == wire.bound(noise.nbytes)  # never larger than the bound
    assert (wire.decode(msg, noise.nbytes)[0] == noise).all()


@pytest.mark.parametrize("codec", ["lz4", "zstd"])
def test_a_corrupt_or_short_message_is_refused_with_its_reason(codec):
    packed = _image().reshape(-1).copy()
    msg = wire.encode(packed.copy(), wire.parse(codec))
    bad = msg.copy()
    bad[wire.HEADER_BYTES + msg.nbytes // 3:] ^= 0x5A  # the payload's tail flipped: the checksum or the format
    with pytest.raises(wire.WireError, match="does not decode"):
        wire.decode(bad, packed.nbytes)
    box = np.zeros(wire.bound(packed.nbytes), np.uint8)  # as MPI leaves it: a receive buffer, partly written
    box[:msg.nbytes - 10] = msg[:-10]
    with pytest.raises(wire.WireError, match="short"):
        wire.decode(box, packed.nbytes, msg.nbytes - 10)
    with pytest.raises(wire.WireError, match="shorter than its header"):
        wire.decode(msg[:10], packed.nbytes)
    with pytest.raises(wire.WireError, match="expected"):
        wire.decode(msg, packed.nbytes + 3)
    head = msg.copy()
    head[:4] = 0
    with pytest.raises(wire.WireError, match="not multigpu's"):
        wire.decode(head, packed.nbytes)


def test_a_lossy_message_drops_only_low_colour_bits_and_says_so():
    img = _image()
    packed = img.reshape(-1).copy()
    colour = packed.nbytes
    msg = wire.encode(packed.copy(), wire.Codec("zstd"), colour=colour, bits=3)
    exact = wire.encode(img.reshape(-1).copy(), wire.Codec("zstd"))
    assert msg.nbytes <= exact.nbytes
    got, bits = wire.decode(msg, colour)
    assert bits == 3 and (got == (img.reshape(-1) & 0xF8)).all()


def _pieces(rng, n):
    """``n`` parts of random sizes with their colour and depth."""
    parts, rendered, rects = [], [], []
    for i in range(n):
        w, h = (int(v) for v in rng.integers(1, 30, 2))
        rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        z = rng.random((h, w), dtype=np.float32)
        rects.append((0, 0, w, h))
        rendered.append((rgb, z))
        parts.append(Piece(0, 1, i, (0, 0, w, h)))
    return parts, rendered, rects


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 6), st.booleans(), st.integers(0, 2 ** 32 - 1))
def test_planar_packing_gives_back_every_part(n, with_depth, seed):
    rng = np.random.default_rng(seed)
    parts, rendered, rects = _pieces(rng, n)
    buf = np.empty(sum(p.pixels for p in parts) * (7 if with_depth else 3), np.uint8)
    _pack_planar(buf, parts, rects, rendered, with_depth)
    msg = wire.encode(buf, wire.Codec("zstd", least=0))
    got, bits = wire.decode(msg, buf.nbytes)
    for (p, rgb, z), (want_rgb, want_z) in zip(_unpack_planar(got, parts, with_depth, bits), rendered):
        assert (rgb == want_rgb).all()
        assert (z is None) == (not with_depth)
        if with_depth:
            assert z.dtype == np.float32 and (z.view(np.uint32) == want_z.view(np.uint32)).all()


def test_a_corrupt_piece_names_the_rank_the_frame_and_the_sender():
    rng = np.random.default_rng(3)
    parts, rendered, rects = _pieces(rng, 2)
    raw = sum(p.pixels for p in parts) * 3
    inbox = {1: np.zeros(wire.bound(raw), np.uint8)}  # nothing arrived but zeros
    posted = Posted(0, [rects, rects], rendered, {1: parts}, [], [], inbox, Sent(0, 0), False, frozenset(), 17,
                    {1: wire.AUTO})
    with pytest.raises(CorruptPiece, match=r"^rank 0: frame 17: the pieces from rank 1: .*not multigpu's"):
        posted._decoded(1, parts)


def test_both_ends_of_a_link_agree_and_auto_compresses_only_between_pcs():
    hosts = ["a", "a", "b", "c"]
    for setting in ("auto", "none", "lz4", "zstd:5"):
        every = [wire.links(setting, hosts, me) for me in range(4)]
        for me in range(4):
            for r, codec in every[me].items():
                assert every[r].get(me) == codec and r != me
    assert set(wire.links("auto", hosts, 0)) == {2, 3} and wire.links("auto", hosts, 0)[2] == wire.AUTO
    assert wire.links("none", hosts, 0) == {} and set(wire.links("lz4", hosts, 0)) == {1, 2, 3}
    assert wire.describe("auto", hosts) == "zstd:1 between PCs" and wire.describe("auto", ["a", "a"]) == "none (one PC)"


@pytest.mark.parametrize("text", ["zip", "lz4:3", "zstd:0", "zstd:20", "zstd:x"])
def test_a_codec_the_wire_does_not_know_is_refused(text):
    with pytest.raises(ValueError):
        wire.parse(text)
