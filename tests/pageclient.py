"""A test's client of the operator's page (``--panel``) over its websocket: what the page has
been sent (rows, status, the summary, errors, every scene time shown), and a wait for a condition
on it, bounded. ``drive`` runs a script against a ``test_panel_mpi.Job`` and ends the job, by id."""

from __future__ import annotations

import asyncio
import json


class Page:
    """What one page connection has seen so far."""

    def __init__(self, ws):
        self.ws = ws
        self.rows, self.status, self.summary, self.errors, self.times = 0, {}, None, [], []

    async def send(self, **message) -> None:
        await self.ws.send(json.dumps(message))

    async def until(self, cond, timeout: float = 90.0) -> None:
        """Read what the page is sent until ``cond()`` holds (an assertion after ``timeout`` s)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while not cond():
            left = deadline - loop.time()
            assert left > 0, f"timed out: {self.rows} rows, {self.status}"
            try:
                m = await asyncio.wait_for(self.ws.recv(), left)
            except asyncio.TimeoutError:
                continue
            if not isinstance(m, str):
                continue
            m = json.loads(m)
            self.rows += len(m.get("rows", []))
            self.status.update(m.get("status", {}))
            if m.get("status", {}).get("scene_time") is not None:
                self.times.append(m["status"]["scene_time"])
            self.summary = m.get("summary", self.summary)
            if "error" in m:
                self.errors.append(m["error"])

    async def more_rows(self, n: int) -> None:
        at = self.rows
        await self.until(lambda: self.rows >= at + n)


def drive(job, script, wait: float = 120) -> tuple[int, Page]:
    """``await script(page)`` against ``job``'s page, then the job's exit code (killed if it
    outlives ``wait`` s or the script fails)."""
    from websockets.asyncio.client import connect

    async def run(url: str) -> Page:
        base, query = url.split("?", 1)
        async with connect(base.replace("http", "ws", 1) + "ws?" + query, open_timeout=60) as ws:
            page = Page(ws)
            await script(page)
            return page

    try:
        page = asyncio.run(run(job.url()))
        code = job.wait(wait)
    finally:
        if job.proc.poll() is None:
            job.kill()
            job.wait(30)
    return code, page
