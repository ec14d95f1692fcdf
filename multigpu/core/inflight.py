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

What orders the ranks, and so which buffers a frame may reuse (``slots``): a rank's ``deliver`` of
frame f first lands the timing row of frame f - 1, which every rank posts only once it has composed
frame f - 1 (``rank/rows.py``); then it waits for every rank to have sent frame f (the
exchange's barrier). No other wait keeps ranks together with frames in flight. A rank held back
while it reads frame f's parts out of its peers' shared slices lets a peer go on until it blocks
in ``deliver`` of f + 1 (f's row is not posted yet), having sent frame f + 1 + N - ``read_lag``:
``held_back_reach``. A ring of ``slots`` buffers per rank is safe when that frame never lands in
the slot being read (tests/test_inflight.py checks every latency by walking the schedule).
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


def held_back_reach(latency: int) -> int:
    """How many frames past frame f a rank may send (and so write to its shared slice) while a
    peer still reads frame f's parts: the rows' and the exchange's waits allow no more. In the
    strict order a row lands as it is posted, so no rank sends f + 1 before every rank composed f."""
    return 0 if latency == 0 else 1 + latency - read_lag(latency)


def slots(latency: int) -> int:
    """Frames a rank's slice of a host's shared segment holds at once: enough that no frame a
    rank may write while a peer still reads frame f falls in f's slot: 3 at latency 1 and 2, 4 at
    latency 3; the strict order would do with one and keeps two (a frame's slice is not rewritten
    by the next one while its row lands)."""
    return max(2, held_back_reach(latency) + 1)
