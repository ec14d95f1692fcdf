"""The walkthrough's configuration, validated once at the door (before any MPI collective)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from multigpu.core.canvas import MOST_TILES, Canvas
from multigpu.core.eyes import EYE_SEPARATION
from multigpu.core.inflight import MOST
from multigpu.core.resample import MIN_SCALE
from multigpu.errors import InputError
from multigpu.options import check, option, register
from multigpu.readers import (  # noqa: F401 (the readers' home; other modules read them from here too)
    MONITOR_BESIDE,
    parse_pair,
    parse_vec3,
    read_labels,
    read_monitor,
    read_mullion,
    read_pair,
    read_panel,
    read_vec3,
)
from multigpu.scene.models import SceneSpec
from multigpu.scene.paths import DEFAULT_FRAMES
from multigpu.strategies import REGISTRY
from multigpu.viewing import DEFAULT_PITCH_MM, check_viewer, read_size_m, read_tracker, splits_by_eye, viewer_of

#: rank 0 rewrites summary.json every this many frames (and whenever the run ends)
SUMMARY_EVERY = 50
#: defaults that the launcher and the rank's job read before a WalkConfig exists (one place each)
DEFAULT_OUT = "out"
DEFAULT_LIVENESS = 30.0  # seconds a silent peer is taken for a dead one


def default_recover(present: str) -> int:
    """``--recover``'s default: 3 restarts with windows on a wall, none headless."""
    return 3 if present == "window" else 0
#: setup (building a scene cache, loading a big model) may take this long on a live rank;
#: a stopped rank is caught by the liveness check long before
SETUP_SECONDS = 1800.0
#: where composed tiles go besides the outputs: nowhere, or a window on each rank's display
PRESENTERS = ("headless", "window")
#: frame exchange backends (``auto``: a shared segment per host where it can be made, messages
#: between hosts; else messages alone)
EXCHANGES = ("auto", "messages", "shared")


def _eye_plans() -> tuple:
    from multigpu.core.stereo import EYE_PLANS

    return EYE_PLANS


def _stereo_modes() -> tuple:
    from multigpu.core.stereo import MODES, UNSHOWN

    return (*MODES, *UNSHOWN)


def _codec(text: str) -> bool:
    """``--compress``: auto, or a codec ``core.wire.parse`` reads."""
    from multigpu.core.wire import parse

    if text == "auto":
        return True
    try:
        parse(text)
    except ValueError:
        return False
    return True


#: who projects the object bounds (``each``: every rank all of them; ``shared``: the host's ranks a
#: slice each, into one shared array, where it can be made: it pays on scenes of 50k objects and
#: more, docs/USAGE.md)
PROJECTIONS = ("each", "shared")
#: ``--path interactive``: the camera is flown by hand from rank 0's window
INTERACTIVE = "interactive"


def setup_timeout(cfg: "WalkConfig") -> float:
    """How long a rank waits for the others to finish setup."""
    return max(cfg.timeout, SETUP_SECONDS)


def _pair(v) -> str:
    return f"{v[0]}x{v[1]}"


def _names(module: str, name: str):
    """A registry's names, looked up when a value is checked or the help is made (its module
    imports more than the door needs: GL, the decompositions, the scene's looks)."""
    import importlib

    return lambda: getattr(importlib.import_module(module), name)


def _strategies() -> str:
    from multigpu.strategies import describe

    return f"the balancing strategy. {describe()}"


def _frames() -> str:
    kinds = ", ".join(f"{k} {v}" for k, v in DEFAULT_FRAMES.items())
    return f"frames to render (default: the whole path; generated: {kinds})"


_finite = lambda v: math.isfinite(v)  # noqa: E731
PATH, WALL, STEREO, BALANCING, QUALITY, OUTPUTS, CONTROL = ("camera path", "wall and display",
                                                           "stereo and the viewer", "balancing",
                                                           "speed for accuracy", "outputs", "run control")
#: the walkthrough's flag groups, in the help's order (the scene's come first, the launcher's hosts last)
GROUPS = [PATH, WALL, STEREO, BALANCING, QUALITY, OUTPUTS, CONTROL]


@dataclass(frozen=True)
class WalkConfig:
    """Everything one walkthrough run needs, each setting declared once with its flag
    (``options.py``). ``grid`` is (rows, cols), ``tile`` (tw, th)."""

    scene: SceneSpec = field(default_factory=SceneSpec)
    # -- camera path
    path: str | None = option(None, group=PATH, metavar="FILE", help=(
        "camera path JSON file, or 'interactive': fly by hand from rank 0's window, starting where --path-kind "
        "starts (needs --present window; H prints the keys) (default: a generated path)"))
    path_kind: str = option("walkthrough", group=PATH, choices=lambda: DEFAULT_FRAMES,
                            help="the generated path when no --path is given")
    frames: int | None = option(None, group=PATH, metavar="N", type=int, valid=lambda v: v is None or v >= 1,
                                must="must be >= 1", help=_frames)
    offset: tuple[float, float, float] = option(
        (0.0, 0.0, 0.0), group=PATH, metavar="X,Y,Z", read=read_vec3, text="0,0,0",
        valid=lambda v: len(v) == 3 and all(_finite(x) and abs(x) <= 1e15 for x in v),
        must="must be three finite numbers of magnitude <= 1e15",
        help="move scene and path by these world units (e.g. 1e8,0,0: far from the origin)")
    # -- wall and display
    grid: tuple[int, int] = option((2, 2), group=WALL, metavar="ROWSxCOLS", read=read_pair, show=_pair,
                                   valid=lambda v: v[0] * v[1] <= MOST_TILES, must=f"must be <= {MOST_TILES} tiles",
                                   help="display wall; ranks = rows*cols (default: {default})")
    tile: tuple[int, int] = option((256, 256), group=WALL, metavar="WxH", read=read_pair, show=_pair,
                                   valid=lambda v: max(v) <= 16384, must="must be at most 16384 pixels per side",
                                   help="pixels per display tile (default: {default})")
    mullion: tuple[int, int] = option(
        (0, 0), group=WALL, metavar="MXxMY", read=read_mullion, show=_pair,
        valid=lambda v: len(v) == 2 and -16384 < min(v) and max(v) <= 4096,
        must="must be two pixel counts 0..4096 (a projector wall's overlap, from its mpcdi file: negative)",
        help="pixels hidden behind the bezels between tiles: the camera spans them, nobody renders them "
             "(default: {default}; a projector wall's tiles overlap as its mpcdi file's regions do)")
    wall: str | None = option(None, group=WALL, metavar="FILE", help=(
        "wall file (JSON): grid, tile, mullions, each rank's X display and window position; flags override it "
        "(docs/USAGE.md: On a real wall)"))
    present: str = option("headless", group=WALL, choices=lambda: PRESENTERS, help=(
        "window: every rank shows its composed tile in a borderless window on its X display, all tiles swapped "
        "in step"))
    monitor: tuple[int, int] | None = option(None, group=WALL, metavar="X,Y", read=read_monitor, const="beside", help=(
        "an operator view on rank 0's display: the whole wall shrunk, the partition over it, live (at X,Y; "
        "without a value: the wall file's monitor position, else right of the wall)"))
    device: int | None = option(None, group=WALL, metavar="I", type=int, valid=lambda v: v is None or v >= 0,
                                must="must be >= 0", help="EGL device index (default: local rank modulo device count)")
    subfrustum: str = option("auto", group=WALL, choices=_names("multigpu.gpu.methods", "METHODS"),
                             help="how a rank renders its region (docs/ACCURACY.md)")
    displays: tuple = ()  # per rank label: X display name, or None for $DISPLAY (wall file)
    positions: tuple = ()  # per rank label: window position (x, y), or None for the tile's canvas place (wall file)
    right_eye: tuple = ()  # per rank label: a passive tile's right-eye window position, or None (wall file)
    mpcdi: str | None = None  # the wall file's MPCDI file: each projector output's picture in the mosaics
    output_colors: dict = field(default_factory=dict)  # the wall file's colour of each output (``warp/colour.py``)
    mpcdi_right: str | None = None  # a passive projector wall's right eyes' MPCDI file (the wall file's)
    blend: str = option("on", group=WALL, choices=lambda: ("on", "off"), help=(
        "a projector wall's outputs (the wall file's mpcdi): blended in their overlaps, or not (each projector's "
        "whole picture, for aligning them by eye)"))
    fullscreen: tuple = ()  # per rank label: True where its window fills its monitor (wall file)
    gpus: tuple = ()  # per rank label: its EGL device (wall file "gpu"), or None for --device / the default
    screen_m: tuple[float, float] | None = option(
        None, group=WALL, flag="--screen-size", metavar="W,H", read=read_size_m,
        valid=lambda v: v is None or (all(_finite(x) and x > 0 for x in v)), must="must be two sizes > 0 metres",
        help=("the wall's width and height in metres, bezels included: where the viewer's eyes look through it "
              f"(default: the wall file's screen_m, else from its bezel's pixel pitch, else {DEFAULT_PITCH_MM:g} mm "
              "a pixel)"))
    # -- stereo and the viewer (core/eyes.py, core/stereo.py)
    stereo: str = option("mono", group=STEREO, choices=lambda: _stereo_modes(), help=(
        "show both eyes on every display: side-by-side (each eye half the tile's width), top-bottom (the left eye "
        "above), anaglyph (red left, cyan right), passive (two outputs a tile, an eye each at the tile's size: a "
        "window each); quad needs a stereo GL visual (docs/USAGE.md, \"A stereo wall\")"))
    eye_separation: float = option(EYE_SEPARATION, group=STEREO, metavar="M", type=float,
                                   valid=lambda v: v >= 0 and _finite(v), must="must be >= 0 metres",
                                   help="metres between the viewer's eyes (default: {default})")
    swap_eyes: bool = option(False, group=STEREO, switch=True, help="each eye's picture in the other's place")
    eyes: str = option("auto", group=STEREO, choices=lambda: _eye_plans(), help=(
        "how the ranks share a stereo wall's eyes: joint (every rank renders its region for both eyes), split "
        "(eye decomposition: half the ranks render the left eye, half the right, each over twice the pixels; "
        "--decomposition screen, an even number of columns or rows), own (--stereo passive: a rank for each eye of "
        "each tile, 2K ranks for K tiles, each showing its eye's projector), auto: split where the wall can, else "
        "joint (docs/BENCHMARKS.md measures them)"))
    head: tuple[float, float, float] | None = option(None, group=STEREO, metavar="X,Y,Z", read=read_vec3, help=(
        "the viewer's head in metres from the wall's centre (x right, y up, z out of the wall): each tile shows "
        "the scene through the wall from there (default: on the wall's axis, where the wall spans the camera's "
        "field of view)"))
    head_poses: str | None = option(None, group=STEREO, metavar="FILE", help=(
        "the head's pose for every frame, beside the camera path: a JSON list of [x, y, z] or [x, y, z, yaw, "
        "pitch, roll] (metres, degrees)"))
    head_tracker: tuple[str, int] | None = option(
        None, group=STEREO, metavar="[ADDRESS:]PORT", read=lambda v: read_tracker(v),
        show=lambda v: "none" if v is None else f"{v[0]}:{v[1]}", help=(
            "rank 0 takes the head's pose from UDP datagrams on this port, the newest each frame (JSON: "
            "{\"position\": [x, y, z], \"yaw\": .., \"pitch\": .., \"roll\": ..}; 127.0.0.1 unless an ADDRESS "
            "is given (0.0.0.0: a tracker on another PC); docs/USAGE.md, \"A stereo wall\")"))
    world_per_metre: float = option(1.0, group=STEREO, metavar="U", type=float,
                                    valid=lambda v: v > 0 and _finite(v), must="must be > 0",
                                    help="scene units a metre of head motion moves the eye (default: {default})")
    poses: tuple = ()  # the head pose file's poses, read at the door
    focus: bool = False  # no wall size, head or scale given: zero parallax at the scene (core/eyes.focused)
    corners: tuple = ()  # per rank label: its display's room corners (wall file "corners_m"), where the file gives them
    # -- balancing
    balance: str = option("auto", group=BALANCING, choices=lambda: REGISTRY, help=_strategies)
    decomposition: str = option("screen", group=BALANCING, choices=_names("multigpu.decompositions", "REGISTRY"), help=(
        "how a frame is divided: screen = the paper's screen partition (balanced by --balance); db = sort-last "
        "database decomposition, depth-composited; bins = static bin patterns, no balancer; hybrid = the screen "
        "partition (--balance) for most objects, the wide ones drawn once and depth-composited"))
    strips: int = option(2048, group=BALANCING, metavar="N", type=int, valid=lambda v: v >= 2, must="must be >= 2",
                         help="strips per split axis (>= 2)")
    bounds: str = option("box", group=BALANCING, choices=lambda: ("box", "sphere"),
                         help="object bounds: box (8 corners) or sphere")
    bin_size: int = option(64, group=BALANCING, metavar="PX", type=int, valid=lambda v: 1 <= v <= 4096,
                           must="must be 1..4096 pixels", help="bins: pixels per bin side")
    bin_pattern: str = option("diagonal", group=BALANCING, choices=_names("multigpu.decompositions", "PATTERNS"),
                              help="bins: which rank owns a bin")
    db_ranges: str = option("visible", group=BALANCING, choices=_names("multigpu.decompositions", "RANGES"), help=(
        "db: object ranges rebalanced over the visible objects every frame, or fixed by all triangles"))
    partition: str = option("redundant", group=BALANCING, choices=lambda: ("redundant", "broadcast"),
                            help="who computes the partition: every rank, or rank 0 and a broadcast")
    projection: str = option("each", group=BALANCING, choices=lambda: PROJECTIONS, help=(
        "who projects the object bounds: every rank every object, or the ranks of a machine a slice each into "
        "one shared array (pays from ~50k objects)"))
    # frames in flight (core/inflight.py; 0: the strict order). None: by measurement (docs/USAGE.md, "Frames in
    # flight"): 1 headless (the plant walk and the city drive at 4 ranks faster in wall time, a few per cent here),
    # 0 with windows (the swap lock keeps the ranks in step each frame: no faster here, and input comes a frame later)
    latency: int | None = option(None, group=BALANCING, metavar="N", type=int,
                                 valid=lambda v: 0 <= v <= MOST, must=f"must be 0..{MOST} frames", help=(
        "frames in flight: a rank plans and draws the next frames while a frame's pixels travel and show (0: "
        "each frame shown before the next starts; input reaches the screen N frames later; default: 1 headless, "
        "0 with --present window)"))
    exchange: str = option("auto", group=BALANCING, choices=lambda: EXCHANGES, help=(
        "frame exchange: auto = a shared-memory segment per machine where it can be made, messages between "
        "machines; shared = the same, an error where it cannot; messages = point to point"))
    compress: str | None = option(None, group=BALANCING, metavar="auto|none|lz4|zstd[:L]",
                                  valid=lambda v: v is None or _codec(v),
                                  must="must be auto, none, lz4, zstd or zstd:LEVEL (1..19)", help=(
        "pixels on the wire: auto = zstd between PCs, none within one; a codec = that codec on every link that "
        "carries messages (default: the wall file's compress, else auto; docs/USAGE.md, \"A wall of PCs\")"))
    compress_moving: int = option(0, group=QUALITY, metavar="BITS", type=int, valid=lambda v: 0 <= v <= 7,
                                  must="must be 0..7 bits", help=(
        "while the camera moves, drop this many low bits of each colour byte of pixels crossing compressed links "
        "(smaller messages; the first frame the camera stops is exact again; 0: always lossless)"))
    # -- speed for accuracy (core/quality.py)
    target_fps: float | None = option(
        None, group=QUALITY, metavar="F", type=float, valid=lambda v: v is None or (v > 0 and _finite(v)),
        must="must be a frame rate above 0", help=(
            "hold this frame rate while the camera moves: each frame a render scale and a level-of-detail bound "
            "from the last frames' times; a frame whose camera stopped is full quality (default: none, every "
            "frame full quality)"))
    render_scale: float = option(1.0, group=QUALITY, metavar="S", type=float,
                                 valid=lambda v: MIN_SCALE <= v <= 1.0, must=f"must be {MIN_SCALE:g}..1", help=(
        "full quality's share of each side's pixels, 0.25..1 (nearest-neighbour upscaled to the tiles)"))
    lod_error: float = option(0.0, group=QUALITY, metavar="PX", type=float, valid=lambda v: v >= 0 and _finite(v),
                              must="must be >= 0 pixels", help=(
        "full quality's level-of-detail bound: each object at its coarsest level whose error stays within PX "
        "pixels on the wall (0: as modelled)"))
    # -- outputs
    out: str = option(DEFAULT_OUT, group=OUTPUTS, metavar="DIR",
                      help="output directory: timings.csv, summary.json, mosaic/")
    mosaic_every: int = option(100, group=OUTPUTS, metavar="N", type=int, valid=lambda v: v >= 0,
                               must="must be >= 0 (0 = never)",
                               help="write the full wall as a PNG every N frames (0: never)")
    overlay: bool = option(True, group=OUTPUTS, flag="--no-overlay", negate=True,
                           help="no partition overlay beside each mosaic")
    colors: str = option("model", group=OUTPUTS, choices=_names("multigpu.scene.looks", "COLOR_VIEWS"), help=(
        "model: the model's own colours (its materials and vertex colours; one grey where the file has none); "
        "objects: a colour per object, to see what the balancer moves between ranks"))
    video: bool = option(False, group=OUTPUTS, switch=True,
                         help="write mosaic.mp4 of every frame (needs imageio-ffmpeg)")
    timeline: bool = option(False, group=OUTPUTS, switch=True, help=(
        "write timeline.json: every rank's phases, start to end, over the run's last frames (multigpu bench "
        "timeline plots it)"))
    record: str | None = option(None, group=OUTPUTS, metavar="FILE", help=(
        "write every frame's camera to FILE, in the format --path reads (replaying it renders the same images)"))
    # -- run control
    timeout: float = option(120.0, group=CONTROL, metavar="S", type=float, valid=lambda v: v > 0 and _finite(v),
                            must="must be > 0 seconds", help="seconds a rank waits for the others within a frame")
    liveness: float = option(DEFAULT_LIVENESS, group=CONTROL, metavar="S", type=float,
                             valid=lambda v: v >= 0 and _finite(v),
                             must="must be >= 0 seconds (0: off)", help=(
        "seconds without a heartbeat before a rank counts as stopped and the job ends (0: off)"))
    progress: bool = option(True, group=CONTROL, flag="--no-progress", negate=True, help="no progress bar")
    panel: tuple[str, int] | None = option(None, group=CONTROL, metavar="[ADDRESS:]PORT", read=read_panel,
                                           show=lambda v: "none" if v is None else f"{v[0]}:{v[1]}", help=(
        "serve the operator's page for this run from rank 0: the wall live, its plots, its controls (listens on "
        "127.0.0.1 unless an ADDRESS is given; port 0: any; the console prints the URL with its token; "
        "docs/USAGE.md, \"Run the wall from a browser\")"))
    # recovery by relaunch (records/recovery.py): restarts allowed within its WINDOW (None: 3 with windows, an
    # unattended wall heals; 0 headless, where a failure should end a measurement), and the path frame a restart
    # resumes at, continuing the run in --out
    recover: int | None = option(None, group=CONTROL, metavar="N", type=int, valid=lambda v: 0 <= v <= 100,
                                 must="must be 0..100 restarts", help=(
        "restart the job after a failure (a rank or host that dies or freezes), resuming at the first frame not "
        "shown, at most N times in 10 minutes; the launcher's (default: 3 with --present window, 0 headless)"))
    standby: bool = option(False, group=CONTROL, switch=True, help=(
        "with --recover: keep the next job started and waiting while the wall runs (launched, its imports done and, "
        "headless, its scene and GL set up), so a restart skips that part of its dark time; the launcher's (one idle "
        "process per rank)"))
    dark: tuple[int, ...] = option((), group=CONTROL, flag="--dark-tiles", metavar="K,...", read=read_labels, text="",
                                   help=(
        "tiles whose PC is gone: shown black, the rest of the wall shared among every rank (the launcher's "
        "restart without a host that does not answer)"))
    resume_at: int = option(0, group=CONTROL, metavar="F", type=int, valid=lambda v: v >= 0, must="must be >= 0",
                            help=(
        "start at frame F of the camera path, continuing the run already in --out (the launcher's restart after "
        "a failure)"))

    def __post_init__(self):
        self._scene_as_drawn()
        if self.latency is None:
            object.__setattr__(self, "latency", 0 if self.present == "window" else 1)
        if self.recover is None:
            object.__setattr__(self, "recover", default_recover(self.present))
        if self.compress is None:
            object.__setattr__(self, "compress", "auto")
        check(self)
        self._viewer_checked()
        if self.partition == "broadcast" and self.decomposition != "screen":
            raise InputError.of("partition", "broadcast works with --decomposition screen (the balancer's "
                                f"partition), got --decomposition {self.decomposition}")
        if self.path == INTERACTIVE and self.present != "window" and self.panel is None:
            raise InputError.of("path", "interactive needs --present window or --panel: the keyboard and mouse are "
                                f"read from rank 0's window or the panel's page (got --present {self.present})")
        if self.mpcdi_right is not None and (self.stereo != "passive" or self.eyes != "own"):
            raise InputError.of("stereo", f"{self.stereo}: the wall file's mpcdi_right (the right eyes' projectors) "
                                          "needs --stereo passive --eyes own (an eye's projector a rank)")
        if self.mpcdi is not None and self.stereo != "mono" and (self.mpcdi_right is None or self.eyes != "own"):
            raise InputError.of("stereo", f"{self.stereo}: a projector wall (the wall file's mpcdi) shows one eye, "
                                          "unless its file gives the right eyes' projectors (mpcdi_right) and each "
                                          "eye has its ranks (--stereo passive --eyes own)")
        if self.monitor is not None and self.present != "window":
            raise InputError.of("monitor", f"needs --present window (got --present {self.present})")
        if any(not 0 <= k < self.ranks for k in self.dark) or len(set(self.dark)) >= self.ranks:
            raise InputError.of("dark", f"must name some of the tiles 0..{self.ranks - 1}, got {list(self.dark)}")
        W, H = self.canvas.size
        if W > 32768 or H > 32768:
            raise InputError(f"--grid/--tile/--mullion: a {W}x{H} wall exceeds 32768 pixels per side")
        if self.decomposition == "bins":
            bins = -(-self.size[0] // self.bin_size) * -(-self.size[1] // self.bin_size)
            if bins < self.ranks:
                raise InputError.of("bin_size", f"{self.bin_size}: a {self.size[0]}x{self.size[1]} wall has {bins} "
                                    f"bins, fewer than the {self.ranks} ranks")
            if bins > 65536:
                raise InputError.of("bin_size", f"{self.bin_size}: {bins} bins on a {self.size[0]}x{self.size[1]} "
                                    "wall (at most 65536: every bin is a draw per frame)")

    def _viewer_checked(self) -> None:
        """Stereo and the viewer at the door (``viewing.check_viewer``)."""
        check_viewer(self)

    @property
    def eyes_split(self) -> bool:
        """Whether the ranks split by eye (``viewing.splits_by_eye``)."""
        return splits_by_eye(self)

    @property
    def viewer(self):
        """Who looks at the wall (``core/eyes.Viewer``), where a run places one: stereo, a head or
        head poses; None: the camera's own frustum, as always."""
        return viewer_of(self)

    def _scene_as_drawn(self) -> None:
        """The scene prepared with levels of detail only where the run can draw them
        (``--lod-error``, ``--target-fps``): built, cached and held for nothing otherwise."""
        lods = self.lod_error > 0 or self.target_fps is not None or self.panel is not None  # the page may ask
        if self.scene.lods != lods:
            object.__setattr__(self, "scene", replace(self.scene, lods=lods))

    @property
    def ranks(self) -> int:
        """The wall's tiles (a rank each)."""
        return self.grid[0] * self.grid[1]

    @property
    def processes(self) -> int:
        """The job's ranks: a rank a tile, or a rank for each eye of each tile (``--eyes own``)."""
        return 2 * self.ranks if self.eyes == "own" else self.ranks

    @property
    def size(self) -> tuple[int, int]:
        """The visible pixels (W, H): where partitions are planned."""
        return self.canvas.visible

    @property
    def canvas(self) -> Canvas:
        """The wall with its mullions: the camera's frustum, the renderers' framebuffer, the mosaic."""
        return Canvas(self.grid, self.tile, self.mullion, self.dark)


register(WalkConfig)
