"""A frame between the stages of the frame loop (``core/inflight.py`` schedules them): what each
later stage of ``frames.Frames`` needs of it, carried from its submit to its delivery."""

from __future__ import annotations

from dataclasses import dataclass

from multigpu.core.quality import Quality
from multigpu.core.work import Work
from multigpu.rank.timer import Timer


@dataclass(slots=True)
class InFlight:
    """A frame between its stages (``core/inflight.py``): what each later stage needs of it."""

    f: int
    t: Timer
    control: object
    work: Work
    plan: list
    pending: object  # gpu.pending.Pending: the pixels, once read
    drawn: int  # triangles this rank drew
    objects: int  # distinct objects it drew
    balance: int  # the CSV's balance column
    recorded: object  # rank 0 with --record: the camera, in path-file coordinates
    quality: Quality  # the frame's render scale and level-of-detail bound
    composed: Work | None = None  # a stereo wall's: both eyes' parts where they are composed (core/stereo.py)
    picks: list | None = None  # a stereo wall's: where each composed part comes from
    head_at: float = 0.0  # rank 0, a tracked head: when the frame's pose reached the host (time.time)
    step: tuple = ()  # a series': (the step shown, whether it is late) at the frame's submit
    rendered: list | None = None
    started: object = None
