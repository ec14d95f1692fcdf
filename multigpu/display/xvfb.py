"""A virtual X server (Debian's Xvfb) for benchmarks and tests of ``--present window``."""

from __future__ import annotations

import os
import signal
import subprocess
import time


def start_xvfb(*screens: tuple[int, int], wait: float = 20.0, prefix: tuple[str, ...] = (),
               display: str | None = None) -> tuple[subprocess.Popen, str]:
    """Start Xvfb with ``screens`` (W, H) in its own session; its process and display name
    (``:N``, picked by Xvfb, or ``display``: a server started again where one died). RuntimeError
    if it does not come up within ``wait`` seconds. ``prefix``: a command that runs it elsewhere
    (a simulated host's ``nsenter ... --``)."""
    read, write = os.pipe()
    args = [*prefix, "Xvfb", *((display,) if display else ()), "-displayfd", str(write), "-nolisten", "tcp",
            "-noreset"]
    for i, (w, h) in enumerate(screens):
        args += ["-screen", str(i), f"{w}x{h}x24"]
    proc = subprocess.Popen(args, pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    os.close(write)
    data = b""
    deadline = time.monotonic() + wait
    while not data.endswith(b"\n") and time.monotonic() < deadline:
        chunk = os.read(read, 16)
        if not chunk:
            break
        data += chunk
    os.close(read)
    if not data.strip():
        stop_xvfb(proc)
        raise RuntimeError("Xvfb did not start")
    return proc, f":{int(data)}"


def stop_xvfb(proc: subprocess.Popen) -> None:
    """Kill the server by its process group, and reap it."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(10)
