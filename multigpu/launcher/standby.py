"""The launcher's side of ``--standby``: the next job, started while the wall runs and handed the
restart when the wall fails (``rank/standby.py`` is the ranks' side).

The standby is the same command line in a session of its own, with ``ENV`` naming a go file in
a directory of the launcher's. It is started once the running job shows a frame (``after``),
so its imports never compete with a job's own start for the cores. Its ranks launch, start
MPI, import, and wait. ``go`` writes the file (atomically: a rename) and hands back the
standby's process for ``supervise`` to adopt; the next standby starts once that job shows its
first frame. The go file is read by rank 0, so a standby serves jobs whose rank 0 runs on the
launcher's machine: a job on one host.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path

from multigpu.launcher.supervise import end_job, start_job
from multigpu.records.recovery import STANDBY_ENV as ENV

#: seconds a standby told to quit has to leave before it is killed
QUIT_S = 5.0
#: seconds between the launcher's looks for the running job's first frame
LOOK = 0.1


class Standby:
    """The waiting next job of ``launcher`` (``mpirun.Launcher``): ``ranks`` ranks of ``argv``."""

    def __init__(self, launcher, ranks: int, argv: list[str]):
        self.launcher, self.ranks, self.argv = launcher, ranks, argv
        self.where = Path(tempfile.mkdtemp(prefix="multigpu-standby-"))
        self.proc: subprocess.Popen | None = None
        self.go_file: Path | None = None
        self.started = 0
        self.lock = threading.Lock()
        self.era = 0  # a start asked for in an earlier era (before a go or the end) is dropped

    def after(self, job: subprocess.Popen, timings: Path, env: dict) -> None:
        """Start a standby (``env``: the job's environment) once ``job`` writes a frame to
        ``timings`` (it has started: the cores are the wall's again), unless one waits already."""
        era, since = self.era, time.time()

        def look():
            while job.poll() is None:
                try:
                    shown = timings.stat().st_mtime >= since
                except OSError:
                    shown = False
                if shown:
                    with self.lock:
                        proc = self._start(env) if era == self.era and not self._ready() else None
                    if proc is not None:  # the standby's parent: it dies with the thread that started it
                        proc.wait()
                    return
                time.sleep(LOOK)

        threading.Thread(target=look, name="standby", daemon=True).start()

    def _start(self, env: dict) -> subprocess.Popen:
        self._stop()
        self.started += 1
        self.go_file = self.where / f"go-{self.started}.json"
        env = {**env, ENV: str(self.go_file)}
        self.proc = start_job(self.launcher.command(self.ranks, self.argv, env=env), env)
        return self.proc

    def _ready(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def go(self, resume_at: int, history: list[dict]) -> subprocess.Popen | None:
        """Hand the restart to a waiting standby: its process, now the job (None: none waits)."""
        with self.lock:
            self.era += 1
            if not self._ready():
                return None
            self._say({"resume_at": resume_at, "history": history})
            proc, self.proc = self.proc, None
            return proc

    def _say(self, what: dict) -> None:
        tmp = self.go_file.with_suffix(".tmp")
        tmp.write_text(json.dumps(what))
        os.replace(tmp, self.go_file)

    def _stop(self) -> None:
        proc, self.proc = self.proc, None
        if proc is not None:
            end_job(proc)

    def close(self) -> None:
        """No standby any more: the job ended for good. A waiting standby is told to quit (its
        ranks leave MPI as a finished job does), and killed if it has not within ``QUIT_S``."""
        with self.lock:
            self.era += 1
            if self._ready():
                self._say({"quit": True})
                try:
                    self.proc.wait(QUIT_S)
                except subprocess.TimeoutExpired:
                    pass
            self._stop()
        shutil.rmtree(self.where, ignore_errors=True)
