"""Frames in flight (``--latency N``): which frame each stage of the frame loop works on at
each step. Pure: no MPI, no GL.

A frame passes three stages: ``submit`` (input, balancing, the draw calls), ``send`` (its
pixels read back and sent towards their tile owners) and ``deliver`` (the peers' parts waited
for, its tile composed and presented, its timing row gathered). Step k of the loop submits
frame k, sends frame k - ``read_lag`` and delivers frame k - N: with N = 0 a frame goes through
all three in one step (the strict order); with N = 1 the rank submits and sends frame k, then
delivers frame k - 1, whose peers sent their parts a step earlier, so a fast rank goes on
without waiting for a slow one's current frame; from N = 2 the pixels are read a step after
the draw calls too, so the GL draws frame k while the rank's thread reads frame k - 1
(Equalizer's latency; two framebuffers). A frame's input is sampled at its submit and reaches
the screen N steps later.
"""

from __future__ import annotations

#: the most frames in flight (beyond two, nothing more overlaps; memory grows)
MOST = 3


def read_lag(latency: int) -> int:
    """Steps between a frame's draw calls and the read of its pixels."""
    return 1 if latency >= 2 else 0


def step(k: int, last: int | None, latency: int, first: int = 0) -> tuple[int | None, int | None, int | None] | None:
    """The frames step ``k`` submits, sends and delivers (None: none), ``last`` the last frame
    to submit (None: no end yet), ``first`` the first (a resumed run's); None once the last
    frame has been delivered."""
    if last is not None and k - latency > last:
        return None

    def frame(f: int) -> int | None:
        return f if f >= first and (last is None or f <= last) else None

    return frame(k), frame(k - read_lag(latency)), frame(k - latency)
