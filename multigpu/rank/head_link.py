"""Head tracking from the network (``--head-tracker``): rank 0 reads the newest pose a tracker sent
and every rank uses it from the same frame.

The protocol is one JSON object (or list) per UDP datagram, a pose as ``core.eyes.pose_of`` reads
it: ``{"position": [x, y, z], "yaw": .., "pitch": .., "roll": ..}`` in the room's metres and
degrees (docs/USAGE.md, "A stereo wall"). Each frame rank 0 reads at most ``MOST_PER_FRAME``
datagrams without waiting (``core.doors`` checks each) and keeps the newest good pose; a datagram
that does not parse, or puts an eye on or behind the wall, is refused in a rate-limited line (all
are counted) and the last good pose stays.
The pose travels to the other ranks in one small broadcast a frame (bounded by ``--timeout``), so
frames in flight each use the newest pose at their submit. Rank 0 keeps when each pose reached the host
(the kernel's receive stamp), for the motion-to-photon figure in the summary: from there to its
frame shown on rank 0's display, the wait for the next frame to start included.
"""

from __future__ import annotations

import socket
import struct
import time
from collections import deque

import numpy as np

from multigpu.core.doors import Refusal, Refusals, parse_json
from multigpu.core.eyes import Pose, head_problem, pose_of
from multigpu.rank.exchange import wait_all

#: the frames whose motion to photon the summary's figures cover: the run's last ones (a run of days stays flat)
PHOTON_KEPT = 10_000
#: the longest datagram read (a pose is well under 200 bytes)
MOST_BYTES = 2048
#: the most datagrams read a frame: a flood costs the frame loop this many reads, the rest wait
#: in the kernel's buffer (and, once it is full, are dropped there)
MOST_PER_FRAME = 64


class HeadLink:
    """A run's tracked head: rank 0's socket (None elsewhere) and the pose every rank uses."""

    def __init__(self, comm, sock: socket.socket | None, viewer, timeout: float):
        self.comm, self.sock, self.viewer, self.timeout = comm, sock, viewer, timeout
        self.tiles = comm.Get_size()
        self.buf = np.zeros(8)  # have, x, y, z, yaw, pitch, roll, arrival (rank 0's time.time)
        self.received = self.refused = 0
        self.refusals = Refusals("multigpu: warning: head tracker: refused ", per_minute=1)
        self.photon_ms: deque = deque(maxlen=PHOTON_KEPT)  # rank 0: a pose's arrival to its frame shown

    @staticmethod
    def listen(address: str, port: int) -> socket.socket:
        """Rank 0's UDP socket, bound and non-blocking (an OSError where it cannot be)."""
        sock = socket.socket(socket.AF_INET6 if ":" in address else socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((address, port))
        except OSError:
            sock.close()
            raise
        sock.setblocking(False)
        if hasattr(socket, "SO_TIMESTAMPNS"):  # when each datagram reached the host, from the kernel
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_TIMESTAMPNS, 1)
        print(f"multigpu: head tracker: listening for poses on udp {address}:{port}", flush=True)
        return sock

    def _drain(self) -> None:
        """The datagrams waiting (``MOST_PER_FRAME`` at most), the newest good pose kept (rank 0)."""
        for _ in range(MOST_PER_FRAME):
            try:
                data, ancillary, _, sender = self.sock.recvmsg(MOST_BYTES, 64)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            arrived = _arrival(ancillary)
            pose = _parsed(data)
            if isinstance(pose, Pose):
                why = head_problem(pose, self.viewer, self.tiles)
                pose = why if why else pose
            if isinstance(pose, str):
                self.refused += 1
                self.refusals.refuse(f"a pose from {sender[0]}:{sender[1]} ({pose}); the last good pose stays "
                                     "(every refusal is counted in summary.json)")
                continue
            self.received += 1
            self.buf[:] = (1.0, *pose.position, pose.yaw, pose.pitch, pose.roll, arrived)

    def pose(self) -> tuple[Pose | None, float]:
        """This frame's pose (None until a good one came) and, on rank 0, when it reached the host
        (``time.time``'s clock)."""
        if self.sock is not None:
            self._drain()
        if self.comm.Get_size() > 1:
            wait_all([self.comm.Ibcast(self.buf, root=0)], self.timeout, "the head's pose")
        b = self.buf
        if not b[0]:
            return None, 0.0
        return Pose((float(b[1]), float(b[2]), float(b[3])), float(b[4]), float(b[5]), float(b[6])), float(b[7])

    def shown(self, arrived: float) -> None:
        """Rank 0: a frame whose pose arrived at ``arrived`` is on its display now."""
        if self.sock is not None and arrived:
            self.photon_ms.append((time.time() - arrived) * 1e3)

    def report(self) -> dict:
        """Rank 0's figures for summary.json."""
        p = np.asarray(self.photon_ms)
        return {"head_poses_received": self.received, "head_poses_refused": self.refused,
                "head_to_photon_ms_median": float(np.median(p)) if len(p) else None,
                "head_to_photon_ms_p99": float(np.percentile(p, 99)) if len(p) else None}

    def close(self, collective: bool = True) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None


def _arrival(ancillary) -> float:
    """When a datagram reached the host: the kernel's stamp where it gave one, else now."""
    for level, kind, data in ancillary:  # one entry at most
        if level == socket.SOL_SOCKET and kind == getattr(socket, "SO_TIMESTAMPNS", -1) and len(data) >= 16:
            sec, nsec = struct.unpack("qq", data[:16])
            return sec + nsec * 1e-9
    return time.time()


def _parsed(data: bytes) -> Pose | str:
    """A datagram's pose, or why it was refused (never raises: ``core.doors``)."""
    got = parse_json(data, MOST_BYTES)
    return got if isinstance(got, Refusal) else pose_of(got)
