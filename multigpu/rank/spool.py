"""A running simulation's ADIOS2 stream, read on rank 0 as its steps come (``--model adios2:NAME``).

``NAME`` ending in ``.bp`` is a BP5 file, read as it grows (a run that records its steps, followed
live, or replayed once written); any other name is an SST stream (the writer's ``NAME.sst`` contact
file: a live code, its steps handed over the network). Each step's variables (``scene/stream_mesh.py``)
are written as the next file of a series in the run's outputs (``steps/step_NNNNNN.vtu``: the steps
kept beside the mosaics, readable by ParaView, and what a replay plays), and made ready for the wall
by the frame loop's ``make`` (``rank/pushed.message``, from the arrays as they came), which rank 0
then sends every rank at the next frame's start (``rank/pushed.Pushed``): a step appears on every
rank at the same frame. The steps after the first wait for the frame loop (``attach``). A step the
wall cannot use is said in one line and left out; a variable that fits nothing is named once. A step
stamped ``written`` (the writer's ``time.time()``) gives the delay from its write to the first frame
that shows it (``step_delay_ms`` in the timings; the ``step_transfer_ms`` of it until rank 0 had
read it, ``step_kept_ms`` until rank 0 had it made for the wall). The reader and the keeper are daemon
threads: nothing from the stream raises in the frame loop. The ``adios2`` wheel is imported here only.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections import deque
from pathlib import Path

import numpy as np

from multigpu.errors import InputError
from multigpu.scene.stream_mesh import PREFIX  # ``--model adios2:NAME``

#: the series file of step k in the spool
NAME = "step_{:06d}.vtu"
#: seconds between asks for the next step (the stream's reader waits in Python, the GIL free)
POLL = 0.005
#: a live step's file is written once this many more frames began after it was made (the frame that
#: shows it drawn), or after ``FILE_WAIT`` seconds; a closing spool waits ``FILE_AT_CLOSE`` s for them
FILE_AFTER, FILE_WAIT, FILE_AT_CLOSE = 2, 1.0, 30.0


def is_stream(model: str | None) -> bool:
    """Whether ``--model`` names an ADIOS2 stream or file."""
    return model is not None and str(model).startswith(PREFIX)


def spool_dir(out) -> Path:
    """Where a run keeps its stream's steps: ``steps/`` in its output directory."""
    return Path(out) / "steps"


def spool_glob(out) -> str:
    """The series (``scene/series.py``) of the steps kept in ``out``."""
    return str(spool_dir(out) / "step_*.vtu")


class Spool:
    """Reads the stream ``model`` (``adios2:NAME``) in a daemon thread into ``where``: ``count``
    steps kept so far, ``ended`` once the writer closed it, ``error`` a line where it could not be
    opened; ``arrived`` when the last step came (``time.monotonic``)."""

    def __init__(self, model: str, where: Path, timeout: float, say=print):
        self.name = str(model)[len(PREFIX):]
        self.model, self.where, self.timeout, self.say = str(model), Path(where), float(timeout), say
        self.where.mkdir(parents=True, exist_ok=True)
        self.count, self.ended, self.error, self.arrived = 0, False, None, time.monotonic()
        self.refused = 0  # steps that could not be used
        # ``(step, mesh, file, write) -> message``: each step after the first made ready for the wall before it
        # is kept (``write()`` keeps it now, where the making needs its file)
        # (the frame loop's, ``attach``); the steps made and not sent yet: (step, message)
        self.make, self._made = None, deque()
        self._attached = threading.Event()
        self.stamps: dict[int, tuple[float, float, float]] = {}  # kept step -> (written, came, kept), where stamped
        self._noted: set[str] = set()
        self._closed = False
        self.engine = "BP5" if self.name.lower().rstrip("/").endswith(".bp") else "SST"
        self.passed = 0  # a live stream's steps passed over while the one before was being kept
        self._pending: deque = deque()
        self._busy = False  # the keeper holds a step it has not made (or left out) yet
        self._asked = 0  # frames that asked for a made step (``next_made``: one a frame, at its start)
        self._files: deque = deque()  # a live stream's steps sent, their files to write: (after ask, write)
        self._cv = threading.Condition()
        self.thread = threading.Thread(target=self._run, name="adios2 stream", daemon=True)
        self.keeper = threading.Thread(target=self._keeper, name="adios2 steps", daemon=True)
        self.filer = threading.Thread(target=self._filer, name="adios2 files", daemon=True)
        self.thread.start()
        self.keeper.start()
        self.filer.start()

    def first(self) -> None:
        """Wait (bounded: ``timeout``) for the first step, or raise the one line saying why none came."""
        end = time.monotonic() + self.timeout
        while self.count == 0 and self.error is None and not self.ended and time.monotonic() < end:
            time.sleep(0.02)
        if self.count:
            return
        why = self.error or ("the stream ended before a step the wall could use" if self.ended else
                             f"no step arrived in {self.timeout:g} s (--timeout; is the simulation writing "
                             f"{self.name}{'' if self.engine == 'BP5' else '.sst'}?)")
        raise InputError.of("model", f"{self.model}: {why}")

    def attach(self, make) -> None:
        """The frame loop is there: each later step is kept and made by ``make`` (``made``)."""
        self.make = make
        self._attached.set()

    def next_made(self, after: int, wait: float = 0.0) -> tuple[int, bytearray] | None:
        """The step made for the wall to send after step ``after`` was, ``(step, message)``: a live
        stream's newest (the wall shows steps as they come), a file's next (it plays every step);
        None: none yet. ``wait``: where a live stream's step is being made, up to that many seconds
        for it, the caller's GIL free (the frame loop's GL calls hold it: the keeper, a thread of the
        same process, would otherwise make it in the gaps between them)."""
        with self._cv:
            self._asked += 1
            self._cv.notify_all()
            if wait > 0 and self.engine == "SST":
                self._cv.wait_for(lambda: self._closed or not (self._busy or self._pending) or
                                  (self._made and self._made[-1][0] > after), wait)
            while self._made and self._made[0][0] <= after:
                self._made.popleft()
                self._cv.notify_all()
            if not self._made:
                return None
            return self._made[-1] if self.engine == "SST" else self._made[0]

    def close(self) -> None:
        """Stop reading; the files of the steps sent are written first (bounded: ``FILE_AT_CLOSE``)."""
        with self._cv:
            self._closed = True
            self._cv.notify_all()
        self._attached.set()
        self.filer.join(FILE_AT_CLOSE)

    def _run(self) -> None:
        try:
            import adios2
        except ImportError as exc:
            self.error = f"the adios2 package is not installed (pip install adios2): {exc}"
            return
        try:
            io = adios2.Adios().declare_io("multigpu")
            io.set_engine(self.engine)
            io.set_parameters({"OpenTimeoutSecs": str(max(1, int(self.timeout)))})
            stream = adios2.Stream(io, self.name, "r")
        except Exception as exc:  # noqa: BLE001 (ADIOS2 raises RuntimeError with its own words)
            self.error = f"cannot open as {self.engine} ({_first_line(exc)})"
            return
        ok, not_ready = adios2.bindings.StepStatus.OK, adios2.bindings.StepStatus.NotReady
        # the wheel's BeginStep holds the GIL while it waits (measured: a thread blocked in it left rank 0's
        # frame loop running only when a step came), and the SST reader crashed after 0.1 s timeouts: so it
        # is asked without waiting, and this thread sleeps between asks (the GIL free)
        try:
            while not self._closed:
                status = stream.begin_step(timeout=0.0)
                if status == not_ready:
                    time.sleep(POLL)
                    continue
                if status != ok:
                    break
                values, skipped, came = {}, [], time.time()
                for name, info in stream.available_variables().items():
                    if info.get("Type") == "string":
                        skipped.append(name)
                        continue
                    values[name] = stream.read(name)
                stream.end_step()
                self._hand((values, skipped, came))
        except Exception as exc:  # noqa: BLE001 (a broken stream ends what the wall gets, never the frame loop)
            self._note(f"{self.model}: the stream failed ({_first_line(exc)}); the wall holds its last step")
        finally:
            self._hand(None)  # the end, after every step handed over
            try:
                stream.close()
            except Exception:  # noqa: BLE001
                pass

    def _hand(self, item) -> None:
        """A step read (None: the stream's end) to the keeper: a live stream's newest replaces one
        not kept yet (the wall shows steps as they come, not late ones), a file's waits its turn."""
        with self._cv:
            if item is not None and self.engine == "SST" and self._pending and self._pending[-1] is not None:
                self._pending.pop()
                self.passed += 1
            while item is not None and self.engine != "SST" and len(self._pending) >= 2 and not self._closed:
                self._cv.wait(0.1)
            self._pending.append(item)
            self._cv.notify_all()

    def _keeper(self) -> None:
        """Keeps the steps read, in a thread apart from the reading (a step read never waits on one kept)."""
        while True:
            with self._cv:
                while not self._pending and not self._closed:
                    self._cv.wait(0.5)
                if self._closed:
                    return
                item = self._pending.popleft()
                self._busy = item is not None
                self._cv.notify_all()
            if item is None:
                self.ended = True
                return
            while self.count and not self._attached.wait(0.5) and not self._closed:
                pass  # the steps after the first: once the frame loop makes them (``attach``)
            if self._closed:
                return
            try:
                self._keep(*item)
            except Exception as exc:  # noqa: BLE001 (a step that cannot be kept is said, never raised)
                self.refused += 1
                self._note(f"{self.model}: a step could not be kept ({_first_line(exc)})")
            finally:
                self._made_one()

    def _made_one(self) -> None:
        with self._cv:
            self._busy = False
            self._cv.notify_all()

    def _keep(self, values: dict, skipped: list[str], came: float) -> None:
        """One step's variables as the next file of the series (written whole, then renamed); where
        the writer stamped it (``written``: its clock's seconds, a host's clock), when it was written
        and when it came (``stamps``: the delay to the wall, in the timings)."""
        written = values.pop("written", None)
        import meshio

        from multigpu.scene.stream_mesh import step_mesh

        for name in skipped:
            self._note(f"{self.model}: variable '{name}' is a string: left out")
        try:
            mesh, _, notes = step_mesh(values, self.count + self.refused, self.model)
        except InputError as exc:
            self.refused += 1
            self._say(f"{exc.message}; the step is left out")
            return
        for n in notes:
            self._note(n.split(": step ", 1)[0] + ": " + n.split(": ", 2)[-1])
        k, path = self.count, self.where / NAME.format(self.count)
        written_to = []

        def write() -> None:  # the step's file: written whole, then renamed; once
            if not written_to:
                tmp = path.with_name(f".{path.stem}-{os.getpid()}.vtu")
                meshio.write(tmp, mesh, binary=True, compression=None)  # zlib: 21 ms for a 96x96 plate, raw 3
                tmp.replace(path)
                written_to.append(path)
        made = None
        if self.make is not None:  # made for the wall first (from the arrays as they came), kept after
            try:
                made = self.make(k, mesh, path, write)
            except Exception as exc:  # noqa: BLE001 (a step the wall cannot make is said once and left out)
                self.refused += 1
                self._note(f"{self.model}: step {k + self.refused - 1}: {_first_line(exc)}; the step is left out")
                path.unlink(missing_ok=True)
                return
        if written is not None and np.size(written) == 1 and np.isfinite(written).all():
            self.stamps[k] = (float(np.ravel(written)[0]), came, time.time())
        later = made is not None and self.engine == "SST"
        if made is not None:
            with self._cv:  # a live stream's newest replaces those not sent; a file's waits its turn
                if self.engine == "SST":
                    self._made.clear()
                while len(self._made) >= 2 and not self._closed:
                    self._cv.wait(0.1)
                self._made.append((k, made))
                self._busy = False  # (sent from now on; its file is written after)
                if later:  # after the frame that shows it has begun drawing (``_filer``)
                    self._files.append((self._asked + FILE_AFTER, write))
                self._cv.notify_all()
        try:
            if not later:
                write()
        finally:  # (a step the wall shows but could not keep is said: the keeper's note)
            self.count += 1
            self.arrived = time.monotonic()

    def _filer(self) -> None:
        """Writes a live stream's sent steps' files once ``FILE_AFTER`` more frames asked for a step
        (their CPU, some 5 ms a 96x96 plate, and the GIL kept out of the frame that shows the step),
        or ``FILE_WAIT`` seconds passed (a paused wall); all at once when the spool closes."""
        while True:
            with self._cv:
                while not self._files and not self._closed:
                    self._cv.wait(0.5)
                if not self._files:
                    return
                due, write = self._files[0]
                self._cv.wait_for(lambda: self._closed or self._asked >= due, FILE_WAIT)
                self._files.popleft()
            try:
                write()
            except Exception as exc:  # noqa: BLE001 (said once, never raised: the wall goes on)
                self._note(f"{self.model}: a step could not be kept ({_first_line(exc)})")

    def _note(self, line: str) -> None:
        """``line`` once per run."""
        if line not in self._noted:
            self._noted.add(line)
            self._say(line)

    def _say(self, line: str) -> None:
        self.say(f"multigpu: warning: {line}", file=sys.stderr, flush=True)


def _first_line(exc: Exception) -> str:
    import re

    text = re.sub(r"\x1b\[[0-9;]*m", "", str(exc)).strip()  # ADIOS2 colours its messages
    return (text.splitlines()[-1] if text else exc.__class__.__name__).strip()
