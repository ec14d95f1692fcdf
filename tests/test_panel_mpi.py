"""The operator's page in a real browser: Debian's Chromium, driven by Playwright, against a real
walk under mpiexec (``--panel 127.0.0.1:0``). One job covers what the issue asks to see: the page
refused without the token and loaded with it, the thumbnail changing as the camera moves, the
plots filling, pause and resume, a strategy switch that reaches every rank at the same frame, a
tampered message refused while the wall goes on, and stop ending the run with exit 0 and whole
timings. Every job runs under a hard timeout and is killed by its process group."""

from __future__ import annotations

import os
import shutil
import threading
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from mpirun import ROOT, SMALL, start_mpi

from multigpu.records.report import BALANCE_NAMES, COLUMNS, read_timings

pytestmark = pytest.mark.mpi

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
#: Chromium as root, offline: no sandbox, no GPU, none of its own network traffic
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]
#: where the test leaves its screenshot for docs/USAGE.md (MULTIGPU_DOC_FIGURES=1: into docs/figures)
SCREENSHOT = ROOT / "docs" / "figures" / "panel.png"


def _browser():
    if CHROMIUM is None:
        pytest.skip("needs Chromium (Debian's chromium package; .ci/run installs it)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("needs playwright (pip install 'multigpu[test]')")
    return sync_playwright


class Job:
    """A walk with a panel, its output read as it comes (the URL is on its first line)."""

    def __init__(self, args: list[str], n: int = 2):
        self.proc, self.kill = start_mpi(n, args)
        self.lines: list[str] = []
        self.err: list[str] = []
        self.readers = [threading.Thread(target=self._read, args=(s, into), daemon=True)
                        for s, into in ((self.proc.stdout, self.lines), (self.proc.stderr, self.err))]
        for r in self.readers:
            r.start()

    def _read(self, stream, into) -> None:
        for line in stream:
            into.append(line)

    def url(self, timeout: float = 180) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and self.proc.poll() is None:
            for line in self.lines:
                if "the panel: http" in line:
                    return line.split("the panel: ", 1)[1].strip()
            time.sleep(0.2)
        raise AssertionError(f"no panel URL: {''.join(self.lines)}{''.join(self.err)[-3000:]}")

    def wait(self, timeout: float = 120) -> int:
        try:
            return self.proc.wait(timeout)
        finally:
            if self.proc.poll() is None:
                self.kill()
                self.proc.wait()
            for r in self.readers:
                r.join(10)

    @property
    def output(self) -> str:
        return "".join(self.lines) + "".join(self.err)


def _status(url: str) -> int:
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status
    except urllib.error.HTTPError as exc:
        return exc.code


def _until(page, expr: str, timeout: float = 60.0):
    """Wait for ``expr`` to hold on the page (as a function: the page's CSP forbids eval)."""
    page.wait_for_function(f"() => ({expr})", timeout=timeout * 1e3)
    return page.evaluate(f"() => ({expr})")


def test_panel_in_chromium(tmp_path):
    sync_playwright = _browser()
    out = tmp_path / "out"
    job = Job(["walkthrough", "--grid", "1x2", "--tile", "160x120", *SMALL, "--frames", "100000",
               "--mosaic-every", "0", "--panel", "127.0.0.1:0", "--out", str(out)])
    try:
        url = job.url()
        base = url.split("?", 1)[0]
        assert url.startswith("http://127.0.0.1:") and "token=" in url
        # without the token (or with a wrong one): refused, the page and its files alike
        assert _status(base) == 403
        assert _status(base + "?token=wrong") == 403
        assert _status(base + "static/panel.js") == 403
        assert _status(url) == 200
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport={"width": 1280, "height": 900})
                page.goto(url)
                # the thumbnail changes as the camera moves; the plots fill
                _until(page, "new Set(window.multigpu.thumbs).size >= 3")
                _until(page, "window.multigpu.rows >= 10")
                assert page.evaluate("() => document.querySelectorAll('#plots canvas').length") >= 4
                assert "2 tiles" in page.inner_text("#header") or "1x2" in page.inner_text("#header")
                # pause: no frame lands while paused; resume: they land again
                page.click("#pause")
                _until(page, "window.multigpu.status.paused === true")
                time.sleep(1.0)
                at = page.evaluate("() => window.multigpu.rows")
                time.sleep(1.5)
                assert page.evaluate("() => window.multigpu.rows") - at <= 3  # frames in flight land, no new ones
                page.click("#pause")
                _until(page, "window.multigpu.status.paused === false")
                _until(page, f"window.multigpu.rows > {at + 5}")
                # a strategy switch reaches every rank at the same frame
                page.select_option("#balance", "cost")
                _until(page, "window.multigpu.status.balance === 'cost'")
                # tampered messages, from a socket of the page's own origin: refused, the wall goes on
                replies = page.evaluate("""async () => {
                    const ws = new WebSocket(`ws://${location.host}/ws`);
                    await new Promise((ok) => ws.onopen = ok);
                    const got = [];
                    ws.onmessage = (ev) => { if (typeof ev.data === 'string') {
                        const m = JSON.parse(ev.data); if (m.error) got.push(m.error); } };
                    for (const bad of ['{"do": "exec", "cmd": "rm -rf /"}', 'not json', '[1, 2]',
                                       '{"do": "render_scale", "value": 1e9}', '{"do": "balance", "name": "../x"}',
                                       '{"do": "stop", "now": true}', 'x'.repeat(5000)])
                        ws.send(bad);
                    await new Promise((ok) => setTimeout(ok, 1500));
                    ws.close();
                    return got;
                }""")
                assert len(replies) == 7, replies
                at = page.evaluate("() => window.multigpu.rows")
                _until(page, f"window.multigpu.rows > {at + 5}")  # the wall went on
                assert job.proc.poll() is None
                page.check("#overlay")  # the partition, drawn by the page over the next thumbnail
                _until(page, "!document.getElementById('parts').hidden")
                page.screenshot(path=str(tmp_path / "panel.png"))
                # stop: the run ends as by Escape, every whole frame kept
                page.click("#stop")
                _until(page, "window.multigpu.summary !== null")
            finally:
                browser.close()
        code = job.wait(120)
    finally:
        if job.proc.poll() is None:
            job.kill()
            job.wait(30)
    assert code == 0, job.output[-3000:]
    assert "stop (the panel)" in job.output
    assert job.output.count("refused a message") == 7 or "more not logged" in job.output
    rows = read_timings(out / "timings.csv")
    col = {c: rows[:, i] for i, c in enumerate(COLUMNS)}
    frames, ranks = col["frame"].astype(int), col["rank"].astype(int)
    n = int(frames.max()) + 1
    assert len(frames) == 2 * n and np.array_equal(np.sort(frames), np.repeat(np.arange(n), 2))
    cost = BALANCE_NAMES.index("cost")
    switched = {int(r): int(frames[(ranks == r) & (col["balance"] == cost)].min()) for r in (0, 1)}
    assert switched[0] == switched[1], switched  # every rank at the same frame
    assert (col["balance"][frames >= switched[0]] == cost).all()
    if os.environ.get("MULTIGPU_DOC_FIGURES"):
        SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(tmp_path / "panel.png", SCREENSHOT)
    _view_in_chromium(sync_playwright, out, n)


def _view_in_chromium(sync_playwright, out, frames: int) -> None:
    """``multigpu view OUT`` over the run just stopped: the same page, every frame in the plots, the
    summary, nothing to control."""
    import subprocess
    import sys

    view = subprocess.Popen([sys.executable, "-m", "multigpu", "view", str(out)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        line = view.stdout.readline()
        assert "multigpu view: http" in line, line + view.stdout.read()
        url = line.split("multigpu view: ", 1)[1].split()[0]
        assert _status(url.split("?")[0]) == 403
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page()
                page.goto(url)
                _until(page, "window.multigpu.summary !== null")
                assert page.evaluate("() => window.multigpu.rows") == frames
                assert page.evaluate("() => window.multigpu.summary.frames_written") == frames
                assert page.is_hidden("#controls")
                page.evaluate("() => document.getElementById('stop').click()")  # hidden, and refused anyway
                _until(page, "window.multigpu.errors.length === 1")
            finally:
                browser.close()
    finally:
        os.killpg(view.pid, 9)
        view.wait(30)


def test_panel_address_taken_is_bad_input(tmp_path):
    """A port already in use: one line naming --panel, exit 2 for the whole job."""
    import socket

    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        job = Job(["walkthrough", "--grid", "1x2", "--tile", "64x64", *SMALL, "--frames", "3", "--panel",
                   f"127.0.0.1:{port}", "--out", str(tmp_path / "out")])
        code = job.wait(180)
    assert code == 2, job.output[-3000:]
    assert "--panel" in job.output and "cannot serve the page" in job.output


def test_fly_record_and_set_quality_from_the_page(tmp_path):
    """A headless interactive run flown from the page alone (no window): held keys and a drag
    move the camera, a recording started and stopped on the page replays as a path file, and a
    render scale set on the page reaches every rank at the same frame."""
    from pageclient import drive

    from multigpu.scene.paths import load_path

    out = tmp_path / "out"
    job = Job(["walkthrough", "--grid", "1x2", "--tile", "96x64", *SMALL, "--path", "interactive",
               "--mosaic-every", "0", "--panel", "127.0.0.1:0", "--out", str(out)])

    async def script(page) -> None:
        await page.until(lambda: page.rows >= 5 and page.status.get("interactive"))
        await page.send(do="record", on=True)
        await page.until(lambda: page.status.get("recording"))
        await page.send(do="keys", held=["forward"])
        await page.more_rows(10)
        await page.send(do="keys", held=[])
        await page.send(do="drag", dx=300, dy=0)
        await page.send(do="render_scale", value=0.5)
        await page.until(lambda: page.status.get("render_scale") == 0.5)
        await page.more_rows(5)
        await page.send(do="record", on=False)
        await page.until(lambda: not page.status.get("recording"))
        await page.send(do="stop")
        await page.until(lambda: page.summary is not None)

    code, page = drive(job, script)
    assert code == 0 and not page.errors, job.output[-3000:]
    assert "stop (the panel)" in job.output
    flown = load_path(out / "recorded-01.json")
    assert len(flown) >= 15
    pos, tgt = np.asarray(flown.position), np.asarray(flown.target)
    assert np.linalg.norm(pos[-1] - pos[0]) > 0  # the held key moved it
    look = (tgt - pos) / np.linalg.norm(tgt - pos, axis=1, keepdims=True)
    assert np.abs(look[-1] - look[0]).max() > 1e-3  # the drag turned it
    rows = read_timings(out / "timings.csv")
    col = {c: rows[:, i] for i, c in enumerate(COLUMNS)}
    frames, scale = col["frame"].astype(int), col["render_scale"]
    assert scale[frames == 0].tolist() == [1.0, 1.0]
    first = {r: int(frames[(col["rank"] == r) & (scale == 0.5)].min()) for r in (0, 1)}
    assert first[0] == first[1]  # every rank from the same frame
