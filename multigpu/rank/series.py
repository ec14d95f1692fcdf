"""A simulation's time series in the frame loop: its steps read ahead in a thread of their own and
shown whole, on every rank from the same frame, never waited for.

Each frame's scene time (``core.motion.scene_time``, the operator's where a run steers it) says
the step it wants (``scene.series.step_at``). The ``Reader`` loads the step wanted next (a cached
scene and its buffers file: one copy per host in the page cache, one rank of the host builds it
while the others wait on a file lock); each rank's timing row says which step it holds ready
(``step_ready``), and once every rank's row of a frame has landed (the same frame on every rank)
each one knows whether all hold the same step. If that step is on the way to the wanted one, every
rank swaps it in at its next frame: the renderer's buffers, the planner's bounds and
decompositions, the part culler and the level chooser (``swap_in``). A step that is late
leaves the wall on the step it shows (``step_late`` in the row), unless ``--late-step wait`` asks every
rank to wait for it at the frame that wants it (every step at its own frames, as a recording wants;
no agreement is needed then). A step that cannot be read is said once, and the series plays on past
it. A live stream's steps come otherwise: rank 0 sends each one to every rank at a frame's start
(``rank/pushed.py``), and every rank swaps it in at that frame. A part of the frame loop with one job.
"""

from __future__ import annotations

import dataclasses
import fcntl
import hashlib
import sys
import threading
import time
from collections import deque

import numpy as np

from multigpu.core.motion import scene_time
from multigpu.errors import InputError
from multigpu.scene.series import after, on_the_way, step_at

#: seconds a rank waits for another rank of its host to build a step before building it itself
LOCK_WAIT = 600.0


class Reader:
    """Loads the steps of ``spec``'s series in a daemon thread, the one asked for last first:
    ``newest`` is the last one loaded, and every loaded step stays until ``keep`` lets it go."""

    def __init__(self, spec, n: int, say=None, path_of=None):
        self.spec, self.n, self.say, self.path_of = spec, n, say, path_of
        self.loaded: dict[int, tuple] = {}  # step -> (scene, buffers file)
        self.newest = -1
        self.bad: dict[int, str] = {}  # steps that could not be read, and why
        self.asked: int | None = None
        self._cv = threading.Condition()
        self._closed = False
        self.thread = threading.Thread(target=self._run, name="series reader", daemon=True)
        self.thread.start()

    def ask(self, k: int) -> None:
        """Load step ``k`` next (a step loaded or refused already is not loaded again)."""
        with self._cv:
            if k in self.loaded:  # loaded already (kept for a row): the one this rank says it holds
                self.newest = k
                return
            if k in self.bad or k == self.asked:
                return
            self.asked = k
            self._cv.notify()

    def wait_for(self, k: int, timeout: float) -> tuple | None:
        """Step ``k``'s (scene, buffers file) once loaded (asked for now), None if it cannot be read;
        a ``TimeoutError`` after ``timeout`` seconds."""
        self.ask(k)
        with self._cv:
            if not self._cv.wait_for(lambda: k in self.loaded or k in self.bad, timeout):
                raise TimeoutError(f"step {k} of the series was not read in {timeout:g} s (--timeout)")
            if k in self.loaded:
                self.newest = k
                return self.loaded[k]
            return None

    def take(self, k: int) -> tuple:
        """Step ``k``'s (scene, buffers file, its renderer's part): loaded (every rank said so)."""
        with self._cv:
            return self.loaded[k]

    def keep(self, steps: set[int]) -> None:
        """Let every loaded step but ``steps`` go (the newest stays: a row may yet say it)."""
        with self._cv:
            for k in [k for k in self.loaded if k not in steps and k != self.newest]:
                del self.loaded[k]

    def close(self) -> None:
        with self._cv:
            self._closed = True
            self.loaded.clear()
            self._cv.notify()

    def _run(self) -> None:
        while True:
            with self._cv:
                while self.asked is None and not self._closed:
                    self._cv.wait()
                if self._closed:
                    return
                k = self.asked
            try:
                got = load_step(self.spec, k, *(() if self.path_of is None else (self.path_of(k), self.path_of(0))))
            except Exception as exc:  # noqa: BLE001 (a thread's failure must never reach the frame loop)
                why = str(exc).splitlines()[0] if str(exc) else exc.__class__.__name__
                with self._cv:
                    self.bad[k] = why
                    if self.asked == k:
                        self.asked = None
                    self._cv.notify_all()
                if self.say is not None:
                    self.say(k, why)
                continue
            with self._cv:
                if self._closed:
                    return
                self.loaded[k], self.newest = got, k
                if self.asked == k:
                    self.asked = None
                self._cv.notify_all()


def load_step(spec, k: int, path=None, first=None) -> tuple:
    """Step ``k`` of ``spec``'s series: its scene (the cache's), buffers file and what the renderer
    takes of them (``gpu.render.ready_step``), built by one rank of the host at a time (a file lock
    beside the cache: the others then map what it wrote).
    ``path``: the step's file, found already, and ``first`` the series' first step's (then loaded
    as ``scene.models.load_step_file`` does, its colours over ``spec``'s fixed range: the same cached
    scene, without looking for the series again)."""
    from multigpu.gpu.buffers import ensure_buffers
    from multigpu.scene.models import cache_dir, load_scene, load_step_file

    load = (lambda: load_scene(dataclasses.replace(spec, step=k))) if path is None else \
        (lambda: load_step_file(spec, path, path if first is None else first))
    where = cache_dir()
    where.mkdir(parents=True, exist_ok=True)
    name = hashlib.sha1(f"{spec.model}\0{k}".encode()).hexdigest()[:16]
    with open(where / f".series-{name}.lock", "a+") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released by the kernel if this process dies
        try:
            scene, info = load()
            shared = ensure_buffers(info.get("cache"), scene)
        except InputError as exc:
            if path is None:
                raise
            raise InputError.of(exc.field or "model", f"step {k} of the series: {exc.message}") from None
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    from multigpu.gpu.render import ready_step

    return scene, shared, ready_step(scene, shared)  # its draw list and mapped pages: the swap is GL calls only


def reader_spec(spec, scene):
    """The spec a series' later steps load with: the colour range its first step was coloured over
    (the series', found once) fixed, so no step looks for the series again."""
    got = scene.meta.get("simulation", {}).get("color_by")
    if spec.color_by is None or spec.color_range is not None or not got:
        return spec
    return dataclasses.replace(spec, color_range=(float(got["range"][0]), float(got["range"][1])))


def step_paths(spec):
    """Step k's file: a file series' as found once, a live stream's by the name rank 0 keeps it by."""
    from pathlib import Path

    if spec.live:
        from multigpu.rank.spool import NAME

        where = Path(spec.model).parent
        return lambda k: where / NAME.format(k)
    from multigpu.scene.series import find_series

    paths = find_series(spec.model).paths
    return lambda k: paths[k]


class Stepping:
    """The series of ``scene`` (its first step, shown now) played at ``spec``'s rate: each frame's
    step decided (``frame``), each row's say (``row``), every rank's rows heard (``landed``)."""

    def __init__(self, scene, spec, rank: int, timeout: float = 60.0, spool=None, comm=None, first=None):
        info = scene.meta["series"]
        self.wait, self.timeout = spec.late_step == "wait", float(timeout)
        self.n, self.shown, self.want = int(info["steps"]), int(info["step"]), int(info["step"])
        self.rate, self.end, self.speed = float(spec.steps_per_second), spec.at_end, float(spec.anim_speed)
        # a live stream's (``rank/spool.py``): the newest step rank 0 kept is the one wanted; no loop
        self.live, self.spool, self.past_end = bool(spec.live), spool, False
        if self.live and self.end == "loop":
            self.end = "hold"
        self.rank = rank
        spec = reader_spec(spec, scene)
        self.reader = self.pushed = self.incoming = None
        if self.live:  # rank 0 sends each step it made to every rank (``rank/pushed.py``)
            self.pushed = self._pushed(spec, comm, first)
        else:
            self.reader = Reader(spec, self.n, self._say if rank == 0 else None, step_paths(spec))
        self.agreed = -1  # the step every rank held ready in the last landed rows (-1: none)
        self.posted: deque[int] = deque()  # the ready steps of this rank's rows not landed yet
        self.last_shown = self.shown  # the step of the last frame shown (``row``: a stream's delay)
        self.swaps = 0
        self.said = None  # the stream's state last said (``say_note``)

    def _pushed(self, spec, comm, given=None):
        """A live run's steps from rank 0 (its keeper makes each one: ``spool.attach``); ``given``:
        the first step as rank 0 sent it (this PC cannot read its file)."""
        from multigpu.rank.pushed import Pushed, message, step_bytes
        from multigpu.scene.models import first_step

        first = step_paths(spec)(0)
        # what each step changes (mapped from the cache, one copy a host; or as rank 0 sent it)
        self.base = given if given is not None else first_step(spec, first)[0]
        self.in_base = True  # the renderer draws the first step's layout (a step built alone is its own)
        if self.spool is not None:
            self.spool.attach(lambda k, mesh, path, write: message(spec, mesh, path, first, write))
        return Pushed(comm, self.timeout, None if self.spool is None else self.spool.next_made, step_bytes(self.base))

    def hear(self) -> None:
        """A live run, at a frame's start on every rank (collective): rank 0's newest step, if new."""
        self.incoming = self.pushed.next()

    def _say(self, k: int, why: str) -> None:
        """A step that cannot be read, once (rank 0; every rank finds the same)."""
        print(f"multigpu: warning: step {k} of the series: {why.removeprefix('--model ')}; the wall shows "
              f"the last step it could read", file=sys.stderr, flush=True)

    def time_of(self, f: int, path=None) -> float:
        """Frame ``f``'s scene time: the path file's (a replay of a steered run), else the frame's."""
        times = getattr(path, "times", None)
        if times is not None and 0 <= f < len(times):
            return float(times[f])
        return scene_time(f, self.speed)

    def frame(self, when: float, replayed: int | None = None) -> tuple | None:
        """The step scene time ``when`` wants: the (scene, buffers file) to swap in now where every
        rank holds one on the way to it (None: the wall keeps its step); the next step asked for.
        ``replayed``: the step a recorded run showed at this frame (its replay waits for it)."""
        if self.live:  # the step rank 0 sent at this frame's start (``hear``), on every rank
            return self._live()
        if replayed is not None and 0 <= replayed < self.n:
            self.want = want = int(replayed)
            self.past_end = when * self.rate >= self.n
        else:
            self.want = want = step_at(when, self.rate, self.n, self.end)
            self.past_end = when * self.rate >= self.n
        swap = None
        waits = self.wait or replayed is not None  # a replay shows what was shown, waiting if it must
        if waits and want != self.shown and want not in self.reader.bad:  # every rank waits for it here
            swap = self.reader.wait_for(want, self.timeout)
            if swap is not None:
                self.shown, self.swaps = want, self.swaps + 1
        elif self.agreed >= 0 and on_the_way(self.shown, self.agreed, want, self.n, self.end):
            swap = self.reader.take(self.agreed)
            self.shown, self.swaps = self.agreed, self.swaps + 1
        nxt = want if want != self.shown else after(self.shown, self.n, self.end)
        for _ in range(self.n):  # past steps that cannot be read: the wall holds, the one after them loads
            if nxt is None or nxt == self.shown or nxt not in self.reader.bad:
                break
            nxt = after(nxt, self.n, self.end)
        if nxt is not None and nxt != self.shown and swap is None:  # (the frame of a swap has enough to do)
            self.reader.ask(nxt)
        return swap

    def _live(self) -> tuple | None:
        got, self.incoming = self.incoming, None
        if got is None:
            return None
        from multigpu.rank.pushed import step_scene

        k, msg = got
        self.want = self.shown = k
        self.n, self.swaps = max(self.n, k + 1), self.swaps + 1
        restep = "changed" in msg and self.in_base  # the layout drawn now is the first step's: vertices only
        self.in_base = "changed" in msg
        return step_scene(self.base, msg), None, None, restep

    def row(self, shown: int, late: bool) -> dict:
        """This rank's say in a frame's row: the step it showed (``shown``, ``late``: at the frame's
        submit) and the one it holds ready now."""
        ready = self.shown if self.live else self.reader.newest  # a stream's: the step it shows (sent whole)
        self.posted.append(ready)
        kept = self.spool.count - 1 if self.spool is not None else -1  # rank 0 of a stream's run: its newest
        row = {"step": shown, "step_ready": ready, "step_late": int(late), "step_wanted": kept}
        if self.spool is not None and shown != self.last_shown and shown in self.spool.stamps:  # first shown now
            written, came, kept = self.spool.stamps[shown]
            row.update(step_delay_ms=(time.time() - written) * 1e3, step_transfer_ms=(came - written) * 1e3,
                       step_kept_ms=(kept - written) * 1e3)
        self.last_shown = shown
        return row

    def landed(self, ready: np.ndarray) -> None:
        """Every rank's ``step_ready`` of a landed frame: the same on every rank, at the same frame."""
        if self.posted:
            self.posted.popleft()
        if self.pushed is not None:  # (rank 0 reuses a board's slot once the frame that read it landed)
            self.pushed.land()
        first = int(ready[0])
        self.agreed = first if first >= 0 and (ready == first).all() else -1
        if self.reader is not None:
            self.reader.keep({self.agreed, *self.posted})

    def ended(self) -> bool:
        """``--at-end stop``: the series' last step was shown and its time is over (a stream: the
        writer closed it and its last step is on the wall; rank 0 knows it, its row stops every rank)."""
        if self.end != "stop":
            return False
        if self.live:
            return self.spool is not None and self.spool.ended and self.shown == self.spool.count - 1
        return self.past_end and self.shown == self.n - 1

    def note(self) -> str | None:
        """What the operator should know of the steps now (rank 0): a stream waited for."""
        if self.spool is None:
            return None
        if self.spool.ended:
            return f"the stream ended after {self.spool.count} steps"
        if time.monotonic() - self.spool.arrived > 1.0 and self.shown == self.spool.count - 1:
            return f"waiting for step {self.spool.count}"
        return None

    def say_note(self, panel=None) -> None:
        """Rank 0: the stream's state (``note``) said once as it changes, and on the page (``panel``)."""
        note = self.note()
        if note is not None and note != self.said:
            print(f"multigpu: {note}", file=sys.stderr, flush=True)
        self.said = note
        if panel is not None:
            panel.step_note = note

    def close(self) -> None:
        if self.reader is not None:
            self.reader.close()


def swap_in(frames, scene, shared, ready=None, restep: bool = False):
    """A series' next step drawn and planned by ``frames`` (``rank/frames.Frames``) from this frame
    on, on every rank at once: its geometry in the renderer (``restep``: only its vertices, the
    layout drawn now being its own), its bounds and objects in the planner, culler and level
    chooser (the frames in flight keep theirs). Returns the scene without its geometry, the frame
    loop's from now on."""
    from multigpu.core.culling import PartCuller
    from multigpu.core.lod import LevelChooser
    from multigpu.scene.moves import movers_of

    eyes = 1 if frames.stereo is None else 2  # submits a frame
    if any(frames.cfg.offset):  # moved as the first step was (``walkthrough.load_world``)
        scene = scene.translated(frames.cfg.offset)
    if restep:
        frames.renderer.restep(scene, keep=(frames.latency + 2) * eyes)
    else:
        frames.renderer.rescene(scene, shared, keep=(frames.latency + 2) * eyes, ready=ready)
    light = scene.without_geometry()  # the GL buffers hold its geometry now
    light.movers = movers_of(light, frames.cfg.scene)
    frames.planner.rescene(light)
    frames.draw.culler = PartCuller(light) if frames.renderer.draws.parts else None
    frames.fidelity.chooser = LevelChooser(light, frames.canvas.size[1])
    return light


def replayed_step(path, f: int) -> int | None:
    """The step a recorded run showed at frame ``f`` (its path file's ``step``), else None."""
    steps = getattr(path, "steps", None)
    return int(steps[f]) if steps is not None and 0 <= f < len(steps) else None


def series_stepping(scene, spec, rank: int, timeout: float = 60.0, spool=None, comm=None,
                    first=None) -> Stepping | None:
    """The frame loop's series part, where the scene is a series' step (None otherwise); ``comm``:
    the ranks a live stream's steps go to, ``first``: the stream's first step as rank 0 sent it."""
    if "series" not in scene.meta:
        return None
    if spec.moving:
        raise InputError.of("moving", "a series' steps do not move as machinery (leave --moving out)")
    return Stepping(scene, spec, rank, timeout, spool, comm, first)
