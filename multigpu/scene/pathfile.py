"""A camera path file written as a flight goes (``--record``): appended to, never rewritten, in
the format ``paths.load_path`` reads (``{"version": 1, "cameras": [...]}``)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np


class PathAppender:
    """A path file written as a flight goes (``--record``): each ``append`` adds cameras at the
    end, so a write costs what it adds however long the flight (a whole rewrite grew with it).

    The file is valid JSON after every append (``{"version": 1, "cameras": [...]}``): the new
    cameras and the closing brackets go in one write over the last closing brackets; a write
    that fails part way is undone (truncated back, brackets restored) and raised.
    """

    TAIL = b"\n]}\n"

    def __init__(self, path: Path):
        self.path = Path(path)
        self.fd = None  # opened at the first camera: a flight of no frames leaves no file
        self.frames = 0
        self.end = 0  # where the closing brackets start

    def append(self, cams: np.ndarray) -> None:
        """``cams``: (F, 12) rows of position, target, up, fov, near, far, or (F, 13) with a
        moving scene's time next (NaN: none; written as each camera's ``time``), or (F, 14) with
        a series' step shown last (NaN: none; each camera's ``step``)."""
        if len(cams) == 0:
            return
        text = ",\n".join(json.dumps({"position": c[0:3].tolist(), "target": c[3:6].tolist(), "up": c[6:9].tolist(),
                                      "fov": float(c[9]), "near": float(c[10]), "far": float(c[11]),
                                      **({"time": float(c[12])} if len(c) > 12 and np.isfinite(c[12]) else {}),
                                      **({"step": int(c[13])} if len(c) > 13 and np.isfinite(c[13]) else {})})
                           for c in cams)
        if self.fd is not None:
            return self._write((",\n" + text).encode(), len(cams))
        self.fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            self._write(('{"version": 1, "cameras": [\n' + text).encode(), len(cams))
        except OSError:  # not even the first cameras: no file rather than an empty path
            self.close()
            self.path.unlink(missing_ok=True)
            raise

    def _write(self, data: bytes, frames: int) -> None:
        data += self.TAIL
        try:
            done = 0
            while done < len(data):
                done += os.pwrite(self.fd, data[done:], self.end + done)
        except OSError:
            try:
                os.ftruncate(self.fd, self.end)
                os.pwrite(self.fd, self.TAIL, self.end)
            except OSError:
                pass
            raise
        self.end += len(data) - len(self.TAIL)
        self.frames += frames

    def resume(self, frames: int) -> None:
        """Go on with the flight already in the file (a restarted run), its first ``frames``
        cameras kept (rewritten once; nothing kept where the file is missing or unreadable)."""
        try:
            cams = json.loads(self.path.read_text())["cameras"][:frames]
            rows = np.array([[*c["position"], *c["target"], *c["up"], c["fov"], c["near"], c["far"],
                              c.get("time", np.nan), c.get("step", np.nan)] for c in cams],
                            dtype=np.float64).reshape(-1, 14)
        except (OSError, ValueError, KeyError, TypeError):
            return
        self.append(rows)

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
