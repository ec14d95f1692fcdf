"""``multigpu view OUT``: the operator's page over a finished run's outputs, so a run can be looked
at rather than read: its facts and summary (summary.json), every frame in the plots
(timings.csv), and its mosaics shown in turn as the wall's thumbnail. Nothing here controls
anything: the page's actions get an error reply. No MPI, no GL.
"""

from __future__ import annotations

import json
import secrets
import sys
import threading
import time
from pathlib import Path

import numpy as np

from multigpu.core.doors import is_whole
from multigpu.errors import InputError
from multigpu.panel.server import PanelServer
from multigpu.panel.state import PanelState, width
from multigpu.panel.state import plot_rows as plot_rows_of

#: seconds each mosaic is shown before the next
SLIDE = 1.0
#: the largest thumbnail side (pixels) a mosaic is shrunk to
THUMB = 640
#: the most ranks a run may say it had, and the most frames plotted (a longer run: every k-th frame)
MOST_RANKS = 4096
MOST_PLOTTED = 20_000


def plot_rows(timings: np.ndarray, ranks: int) -> np.ndarray:
    """timings.csv's rows (``records.report.read_timings``) as the page's plot rows, one a frame
    (``panel.state.names``)."""
    from multigpu.records.report import COLUMNS

    col = {c: i for i, c in enumerate(COLUMNS)}
    if len(timings) < ranks:
        return np.zeros((0, width(ranks)))
    order = np.lexsort((timings[:, col["rank"]], timings[:, col["frame"]]))
    rows = timings[order]
    n = len(rows) // ranks
    return plot_rows_of(rows[: n * ranks].reshape(n, ranks, -1), col)


def load(out: Path) -> tuple[PanelState, list[Path]]:
    """The page's state for the run in ``out`` and its mosaics in frame order."""
    from multigpu.records.report import read_timings

    summary_file, timings_file = out / "summary.json", out / "timings.csv"
    if not summary_file.is_file() or not timings_file.is_file():
        raise InputError(f"{out}: not a run's outputs (needs summary.json and timings.csv)")
    try:
        summary = json.loads(summary_file.read_text())  # our own writer's (NaN where a figure has none)
        timings = read_timings(timings_file)
    except (OSError, ValueError, RecursionError) as exc:
        raise InputError(f"{out}: cannot read the run's outputs ({exc.__class__.__name__}: {str(exc)[:120]})") from None
    if not isinstance(summary, dict):
        raise InputError(f"{summary_file}: not a run's summary (not a JSON object)")
    config = summary.get("config") if isinstance(summary.get("config"), dict) else {}
    placed = config.get("ranks", 1)  # the config's: every rank's placement
    ranks = summary["ranks"] if "ranks" in summary else len(placed) if isinstance(placed, list) else placed
    if not is_whole(ranks, 1, MOST_RANKS):
        raise InputError(f"{summary_file}: ranks must be a whole number 1..{MOST_RANKS}, got {str(ranks)[:40]!r}")
    header = {"title": f"multigpu view: {out}", "run": str(out), **{k: v for k, v in config.items()
                                                                    if not isinstance(v, (dict, list))}}
    events = [f"{'complete' if summary.get('complete') else 'not complete'}: {summary.get('frames_written', 0)} "
              "frames written"]
    if summary.get("stopped_by"):
        events.append(f"stopped by {summary['stopped_by']}")
    rows = plot_rows(timings, ranks)
    if len(rows) > MOST_PLOTTED:  # a run of days: every k-th frame, the last one kept
        rows = rows[np.unique(np.r_[np.arange(0, len(rows), -(-len(rows) // MOST_PLOTTED)), len(rows) - 1])]
    state = PanelState(header, (), ranks, events, history=max(len(rows), 1))
    for row in rows:  # once, at the start
        state.add_row(row)
    state.set_status(state="finished run", view=True)
    state.finish(summary)
    mosaics = sorted(p for p in (out / "mosaic").glob("frame_*.png") if not p.stem.endswith("_partition"))
    return state, mosaics


def _slides(state: PanelState, mosaics: list[Path], stop: threading.Event) -> None:
    """Show the mosaics in turn as the thumbnail, over and over, while a page is connected."""
    from PIL import Image

    i, skipped = 0, set()
    while mosaics and not stop.is_set():
        if (state.clients and len(mosaics) > 1) or state.thumb is None:
            path = mosaics[i % len(mosaics)]
            try:
                with Image.open(path) as im:
                    im.thumbnail((THUMB, THUMB))
                    state.set_thumb(np.asarray(im.convert("RGB")), None, 1)
            except (OSError, ValueError, Image.DecompressionBombError) as exc:  # one bad mosaic: the next
                if path not in skipped:
                    skipped.add(path)
                    print(f"multigpu view: {path}: not shown ({exc.__class__.__name__}: {str(exc)[:120]})",
                          file=sys.stderr, flush=True)
            i += 1
        stop.wait(SLIDE)


def serve(out: str, address: str, port: int) -> int:
    """Serve the page over ``out`` until interrupted; prints its URL."""
    state, mosaics = load(Path(out))
    server = PanelServer(state, address, port, secrets.token_urlsafe(24), readonly=True)
    try:
        url = server.start()
    except OSError as exc:
        raise InputError.of("panel", f"cannot serve the page on {address}:{port} ({exc})") from None
    print(f"multigpu view: {url}  ({len(mosaics)} mosaics; Ctrl-C ends it)", flush=True)
    stop = threading.Event()
    slides = threading.Thread(target=_slides, args=(state, mosaics, stop), daemon=True)
    slides.start()
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        stop.set()
        server.close()
    return 0
