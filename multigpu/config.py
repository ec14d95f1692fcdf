"""The walkthrough's configuration, validated once at the door (before any MPI collective)."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace

from multigpu.core.canvas import Canvas
from multigpu.errors import InputError
from multigpu.scene.models import SceneSpec
from multigpu.scene.paths import DEFAULT_FRAMES  # noqa: F401  (frames of generated paths; re-exported for the CLI)
from multigpu.strategies import REGISTRY

#: rank 0 rewrites summary.json every this many frames (and whenever the run ends)
SUMMARY_EVERY = 50
#: setup (building a scene cache, loading a big model) may take this long on a live rank;
#: a stopped rank is caught by the liveness check long before
SETUP_SECONDS = 1800.0
#: where composed tiles go besides the outputs: nowhere, or a window on each rank's display
PRESENTERS = ("headless", "window")
#: frame exchange backends (``auto``: a shared segment per host where it can be made, messages
#: between hosts; else messages alone)
EXCHANGES = ("auto", "messages", "shared")
#: who projects the object bounds (``each``: every rank all of them; ``shared``: the host's ranks a
#: slice each, into one shared array, where it can be made: it pays on scenes of 50k objects and
#: more, docs/USAGE.md)
PROJECTIONS = ("each", "shared")
#: ``--path interactive``: the camera is flown by hand from rank 0's window
INTERACTIVE = "interactive"
#: ``--monitor`` without a place: right of the wall, on a screen that holds the wall's canvas
MONITOR_BESIDE = (-1, -1)


def setup_timeout(cfg: "WalkConfig") -> float:
    """How long a rank waits for the others to finish setup."""
    return max(cfg.timeout, SETUP_SECONDS)


def parse_vec3(text: str, flag: str) -> tuple[float, float, float]:
    """'X,Y,Z' as three floats, or a clear error naming ``flag``."""
    try:
        v = tuple(float(t) for t in str(text).split(","))
    except ValueError:
        v = ()
    if len(v) != 3:
        raise InputError(f"{flag} must look like X,Y,Z (three numbers), got '{text}'")
    return v


def parse_pair(text: str, flag: str, sep: str = "x") -> tuple[int, int]:
    m = re.fullmatch(rf"\s*(\d+)\s*{sep}\s*(\d+)\s*", str(text))
    if not m:
        raise InputError(f"{flag} must look like A{sep}B with positive integers, got '{text}'")
    a, b = int(m.group(1)), int(m.group(2))
    if a < 1 or b < 1:
        raise InputError(f"{flag} must be positive on both sides, got '{text}'")
    return a, b


@dataclass(frozen=True)
class WalkConfig:
    """Everything one walkthrough run needs. ``grid`` is (rows, cols), ``tile`` (tw, th)."""

    scene: SceneSpec = field(default_factory=SceneSpec)
    path: str | None = None
    path_kind: str = "walkthrough"
    frames: int | None = None
    grid: tuple[int, int] = (2, 2)
    tile: tuple[int, int] = (256, 256)
    strips: int = 2048
    balance: str = "auto"  # cross or strips, whichever the scene's frames favour (docs/RESULTS.md, payoff)
    bounds: str = "box"
    out: str = "out"
    mosaic_every: int = 100
    overlay: bool = True
    video: bool = False
    device: int | None = None
    subfrustum: str = "auto"
    partition: str = "redundant"
    exchange: str = "auto"  # a shared-memory segment per host (messages between hosts) where it can be made
    projection: str = "each"  # every rank projects every object's bounds (``shared``: a slice each per host)
    decomposition: str = "screen"
    bin_size: int = 64
    bin_pattern: str = "diagonal"
    db_ranges: str = "visible"
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    timeout: float = 120.0
    liveness: float = 30.0
    progress: bool = True
    mullion: tuple[int, int] = (0, 0)  # pixels hidden behind the bezels between tiles (MX, MY)
    present: str = "headless"  # or "window": every rank shows its tile in a window on its display
    wall: str | None = None  # the wall file the grid/tile/mullion/displays came from
    displays: tuple = ()  # per rank label: X display name, or None for $DISPLAY
    positions: tuple = ()  # per rank label: window position (x, y), or None for the tile's canvas place
    fullscreen: tuple = ()  # per rank label: True where its window fills its monitor (wall file)
    gpus: tuple = ()  # per rank label: its EGL device (wall file "gpu"), or None for --device / the default
    record: str | None = None  # write every frame's camera here, in the format --path reads
    monitor: tuple[int, int] | None = None  # rank 0's operator view at this place (MONITOR_BESIDE: beside the wall)
    # frames in flight (core/inflight.py; 0: the strict order). None: by measurement (docs/USAGE.md, "Frames in
    # flight"): 1 headless (the plant walk and the city drive at 4 ranks over a third faster in wall time), 0 with
    # windows (the swap lock keeps the ranks in step each frame: no faster here, and input would come a frame later)
    latency: int | None = None
    # speed for accuracy (core/quality.py): a frame rate held while the camera moves; full quality's scale and bound
    target_fps: float | None = None
    render_scale: float = 1.0  # share of each side's pixels drawn (nearest-neighbour upscaled)
    lod_error: float = 0.0  # level-of-detail bound in wall pixels (0: every object as modelled)
    timeline: bool = False  # timeline.json: every rank's phases over the run's last TIMELINE_FRAMES frames
    colors: str = "model"  # the model's own colours, or "objects": a colour per object (scene/looks.py)
    # recovery by relaunch (parallel/recovery.py): restarts allowed within its WINDOW (None: 3 with windows, an
    # unattended wall heals; 0 headless, where a failure should end a measurement), and the path frame a restart
    # resumes at, continuing the run in --out
    recover: int | None = None
    resume_at: int = 0
    dark: tuple[int, ...] = ()  # tiles whose PC is gone: black, drawn by nobody; their ranks stand in elsewhere

    def __post_init__(self):
        self._scene_as_drawn()
        if self.frames is not None and self.frames < 1:
            raise InputError(f"--frames must be >= 1, got {self.frames}")
        if self.strips < 2:
            raise InputError(f"--strips must be >= 2, got {self.strips}")
        if self.balance not in REGISTRY:
            raise InputError(f"--balance must be one of {', '.join(REGISTRY)}, got '{self.balance}'")
        if self.bounds not in ("box", "sphere"):
            raise InputError(f"--bounds must be 'box' or 'sphere', got '{self.bounds}'")
        if self.path_kind not in DEFAULT_FRAMES:
            raise InputError(f"--path-kind must be one of {', '.join(DEFAULT_FRAMES)}, got '{self.path_kind}'")
        if self.mosaic_every < 0:
            raise InputError(f"--mosaic-every must be >= 0 (0 = never), got {self.mosaic_every}")
        from multigpu.gpu.render import METHODS

        if self.subfrustum not in METHODS:
            raise InputError(f"--subfrustum must be one of {', '.join(METHODS)}, got '{self.subfrustum}'")
        if self.exchange not in EXCHANGES:
            raise InputError(f"--exchange must be one of {', '.join(EXCHANGES)}, got '{self.exchange}'")
        if self.projection not in PROJECTIONS:
            raise InputError(f"--projection must be one of {', '.join(PROJECTIONS)}, got '{self.projection}'")
        if self.partition not in ("redundant", "broadcast"):
            raise InputError(f"--partition must be 'redundant' or 'broadcast', got '{self.partition}'")
        from multigpu.decompositions import PATTERNS, RANGES
        from multigpu.decompositions import REGISTRY as DECOMPOSITIONS

        if self.decomposition not in DECOMPOSITIONS:
            raise InputError(f"--decomposition must be one of {', '.join(DECOMPOSITIONS)}, got '{self.decomposition}'")
        if self.bin_pattern not in PATTERNS:
            raise InputError(f"--bin-pattern must be one of {', '.join(PATTERNS)}, got '{self.bin_pattern}'")
        if not 1 <= self.bin_size <= 4096:
            raise InputError(f"--bin-size must be 1..4096 pixels, got {self.bin_size}")
        if self.db_ranges not in RANGES:
            raise InputError(f"--db-ranges must be one of {', '.join(RANGES)}, got '{self.db_ranges}'")
        if self.partition == "broadcast" and self.decomposition != "screen":
            raise InputError("--partition broadcast works with --decomposition screen (the balancer's partition), "
                             f"got --decomposition {self.decomposition}")
        if len(self.offset) != 3 or not all(math.isfinite(v) and abs(v) <= 1e15 for v in self.offset):
            raise InputError(f"--offset must be three finite numbers of magnitude <= 1e15, got {self.offset}")
        from multigpu.core.inflight import MOST

        if self.latency is None:
            object.__setattr__(self, "latency", 0 if self.present == "window" else 1)
        if not 0 <= self.latency <= MOST:
            raise InputError(f"--latency must be 0..{MOST} frames, got {self.latency}")
        self._check_quality()
        if self.device is not None and self.device < 0:
            raise InputError(f"--device must be >= 0, got {self.device}")
        if not (self.timeout > 0 and math.isfinite(self.timeout)):
            raise InputError(f"--timeout must be > 0 seconds, got {self.timeout}")
        self._check_recovery()
        if not (self.liveness >= 0 and math.isfinite(self.liveness)):
            raise InputError(f"--liveness must be >= 0 seconds (0: off), got {self.liveness}")
        if self.present not in PRESENTERS:
            raise InputError(f"--present must be one of {', '.join(PRESENTERS)}, got '{self.present}'")
        if self.path == INTERACTIVE and self.present != "window":
            raise InputError("--path interactive needs --present window: the keyboard and mouse are read from rank 0's "
                             f"window (got --present {self.present})")
        if self.monitor is not None and self.present != "window":
            raise InputError(f"--monitor needs --present window (got --present {self.present})")
        if len(self.mullion) != 2 or min(self.mullion) < 0 or max(self.mullion) > 4096:
            raise InputError(f"--mullion must be two pixel counts 0..4096, got {self.mullion}")
        tw, th = self.tile
        if tw > 16384 or th > 16384:
            raise InputError(f"--tile {tw}x{th}: tiles above 16384 pixels per side are not supported")
        W, H = self.canvas.size
        if W > 32768 or H > 32768:
            raise InputError(f"--grid/--tile/--mullion: a {W}x{H} wall exceeds 32768 pixels per side")
        if self.decomposition == "bins":
            bins = -(-self.size[0] // self.bin_size) * -(-self.size[1] // self.bin_size)
            if bins < self.ranks:
                raise InputError(f"--bin-size {self.bin_size}: a {self.size[0]}x{self.size[1]} wall has {bins} bins, "
                                 f"fewer than the {self.ranks} ranks")
            if bins > 65536:
                raise InputError(f"--bin-size {self.bin_size}: {bins} bins on a {self.size[0]}x{self.size[1]} wall "
                                 "(at most 65536: every bin is a draw per frame)")

    def _scene_as_drawn(self) -> None:
        """The colour view checked, and the scene prepared with levels of detail only where the
        run can draw them (``--lod-error``, ``--target-fps``): built, cached and held for nothing
        otherwise."""
        from multigpu.scene.looks import COLOR_VIEWS

        if self.colors not in COLOR_VIEWS:
            raise InputError(f"--colors must be one of {', '.join(COLOR_VIEWS)}, got '{self.colors}'")
        lods = self.lod_error > 0 or self.target_fps is not None
        if self.scene.lods != lods:
            object.__setattr__(self, "scene", replace(self.scene, lods=lods))
    def _check_recovery(self) -> None:
        """``--recover`` (its default by ``--present``), ``--resume-at`` and ``--dark-tiles``."""
        if self.recover is None:
            object.__setattr__(self, "recover", 3 if self.present == "window" else 0)
        if not 0 <= self.recover <= 100 or self.resume_at < 0:
            raise InputError(f"--recover must be 0..100 restarts and --resume-at >= 0, got {self.recover}, "
                             f"{self.resume_at}")
        if any(not 0 <= k < self.ranks for k in self.dark) or len(set(self.dark)) >= self.ranks:
            raise InputError(f"--dark-tiles must name some of the tiles 0..{self.ranks - 1}, got {list(self.dark)}")

    def _check_quality(self) -> None:
        """Speed for accuracy's flags: a frame rate above 0, a scale the renderer makes, a bound >= 0."""
        if self.target_fps is not None and not (self.target_fps > 0 and math.isfinite(self.target_fps)):
            raise InputError(f"--target-fps must be a frame rate above 0, got {self.target_fps}")
        from multigpu.core.resample import MIN_SCALE

        if not MIN_SCALE <= self.render_scale <= 1.0:
            raise InputError(f"--render-scale must be {MIN_SCALE}..1, got {self.render_scale}")
        if not (self.lod_error >= 0 and math.isfinite(self.lod_error)):
            raise InputError(f"--lod-error must be >= 0 pixels, got {self.lod_error}")

    @property
    def ranks(self) -> int:
        return self.grid[0] * self.grid[1]

    @property
    def size(self) -> tuple[int, int]:
        """The visible pixels (W, H): where partitions are planned."""
        return self.grid[1] * self.tile[0], self.grid[0] * self.tile[1]

    @property
    def canvas(self) -> Canvas:
        """The wall with its mullions: the camera's frustum, the renderers' framebuffer, the mosaic."""
        return Canvas(self.grid, self.tile, self.mullion, self.dark)
