// The operator's page: the run's facts, the wall's thumbnail, live plots, and its controls.
// Everything it shows comes over one WebSocket (/ws); everything it does is one JSON message
// {"do": action, ...} that the server checks before the wall sees it.
"use strict";

const HISTORY = 600;
const MOVES = { w: "forward", arrowup: "forward", s: "back", arrowdown: "back", a: "left", arrowleft: "left",
                d: "right", arrowright: "right", e: "up", pageup: "up", q: "down", pagedown: "down" };
const $ = (id) => document.getElementById(id);
// what tests and people may read: counts and the thumbnails' checksums
const seen = window.multigpu = { rows: 0, thumbs: [], replies: [], errors: [], status: {}, summary: null,
                                 closed: false };

let ws = null, series = [], ranks = 0, data = null, plots = [], wallWidth = 0, status = {}, pieces = null;
const COLOURS = ["#e41a1c", "#377eb8", "#4daf4a", "#984ea3", "#ff7f00", "#ffff33", "#a65628", "#f781bf"];
const held = new Set();

function send(msg) {
  if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(msg));
}

function connect() {
  const token = new URLSearchParams(location.search).get("token");
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws` +
              (token ? `?token=${encodeURIComponent(token)}` : "");
  ws = new WebSocket(url);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => { $("state").textContent = "connected"; };
  ws.onclose = () => {
    seen.closed = true;
    $("state").textContent = seen.summary ? "run ended" : "disconnected (retrying)";
    if (!seen.summary) setTimeout(connect, 1000);  // a wall restarted by --recover serves again
  };
  ws.onmessage = (ev) => {
    if (typeof ev.data !== "string") return thumbnail(ev.data);
    const msg = JSON.parse(ev.data);
    if (msg.hello) hello(msg.hello);
    if (msg.rows) addRows(msg.rows);
    if (msg.status) showStatus(msg.status);
    if (msg.events) for (const [t, text] of msg.events) addEvent(t, text);
    if (msg.summary) showSummary(msg.summary);
    if (msg.thumb) pieces = msg.thumb;  // the next picture's partition
    if (msg.ok) { seen.replies.push(msg.ok); $("reply").textContent = ""; }
    if (msg.error) { seen.errors.push(msg.error); $("reply").textContent = "refused: " + msg.error; }
  };
}

function hello(h) {
  series = h.series; ranks = h.ranks;
  const head = seen.header = h.header;
  $("title").textContent = head.title || "";
  wallWidth = (head.wall_pixels || [0])[0];
  colorBar(head.color_by);
  const table = $("header");
  table.replaceChildren();
  for (const [k, v] of Object.entries(head)) {
    if (k === "title" || k === "color_by") continue;
    const tr = table.insertRow();
    tr.insertCell().textContent = k;
    tr.insertCell().textContent = typeof v === "object" ? JSON.stringify(v) : String(v);
  }
  const sel = $("balance");
  sel.replaceChildren(...h.balances.map((b) => new Option(b, b)));
  sel.disabled = h.balances.length < 2;
  makePlots();
}

function colorBar(cb) {
  // a simulation's colour bar: the field, its range and its colour map as a strip
  $("colorbar").hidden = !cb;
  if (!cb) return;
  $("cbname").textContent = `${cb.field} (${cb.colormap})`;
  $("cblo").textContent = Number(cb.range[0]).toPrecision(4);
  $("cbhi").textContent = Number(cb.range[1]).toPrecision(4);
  $("cbstrip").style.background = `linear-gradient(to right, ${cb.colors.join(", ")})`;
}

function makePlots() {
  for (const p of plots) p.destroy();
  plots = [];
  data = series.map(() => []);
  const box = $("plots");
  box.replaceChildren();
  const width = Math.min(640, Math.max(320, window.innerWidth - 40));
  const colours = COLOURS;
  const rankSeries = [];
  for (let k = 0; k < ranks; k++) rankSeries.push({ label: `rank ${k}`, stroke: colours[k % colours.length] });
  const make = (title, cols, lines) => {
    const el = document.createElement("div");
    box.appendChild(el);
    const p = new uPlot({ title, width, height: 160, scales: { x: { time: false } },
                          series: [{ label: "frame" }, ...lines], legend: { show: lines.length <= 8 } },
                        [[], ...lines.map(() => [])], el);
    p.cols = cols;
    plots.push(p);
  };
  const rankCols = [], renderCols = [];
  for (let k = 0; k < ranks; k++) { rankCols.push(5 + k); renderCols.push(5 + ranks + k); }
  make("frame time per rank (ms)", rankCols, rankSeries);
  make("render CPU per rank (ms): the balance", renderCols, rankSeries.map((s) => ({ ...s })));
  make("frames per second", [1], [{ label: "fps", stroke: "#8c8" }]);
  make("imbalance (slowest / mean render)", [4], [{ label: "imbalance", stroke: "#c96" }]);
  make("swap skew (ms)", [3], [{ label: "skew", stroke: "#69c" }]);
}

function addRows(rows) {
  if (!data) return;
  for (const row of rows) {
    row.forEach((v, i) => data[i].push(v));
  }
  for (const col of data) if (col.length > HISTORY) col.splice(0, col.length - HISTORY);
  seen.rows += rows.length;
  for (const p of plots) p.setData([data[0], ...p.cols.map((c) => data[c])]);
  const last = rows[rows.length - 1];
  if (last && last[1] != null) $("fps").textContent = `frame ${last[0]}: ${last[1].toFixed(1)} fps`;
}

function checksum(bytes) {
  let h = 2166136261;
  for (let i = 0; i < bytes.length; i += 7) h = Math.imul(h ^ bytes[i], 16777619) >>> 0;
  return h;
}

function thumbnail(buf) {
  const bytes = new Uint8Array(buf);
  seen.thumbs.push(checksum(bytes));
  if (seen.thumbs.length > 100) seen.thumbs.shift();
  const img = $("thumb");
  const old = img.src;
  img.src = URL.createObjectURL(new Blob([bytes], { type: "image/jpeg" }));
  if (old && old.startsWith("blob:")) URL.revokeObjectURL(old);
  drawParts(pieces);
}

// the partition over the thumbnail, drawn here (not on the wall's rank 0): each rank's pieces tinted
function drawParts(p) {
  const c = $("parts"), on = $("overlay").checked && p;
  c.hidden = !on;
  if (!on) return;
  c.width = p.width; c.height = p.height;
  const g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  for (const [k, x0, y0, x1, y1] of p.pieces) {
    const colour = COLOURS[k % COLOURS.length];
    g.globalAlpha = 0.18; g.fillStyle = colour; g.fillRect(x0, y0, x1 - x0, y1 - y0);
    g.globalAlpha = 1.0; g.strokeStyle = colour; g.strokeRect(x0 + 0.5, y0 + 0.5, x1 - x0 - 1, y1 - y0 - 1);
  }
}

function showStatus(s) {
  status = seen.status = s;
  $("state").textContent = s.paused ? "paused" : (s.state || "running");
  $("pause").textContent = s.paused ? "resume" : "pause";
  $("record").textContent = s.recording ? "stop recording" : "record";
  $("record").classList.toggle("on", !!s.recording);
  if (s.balance && document.activeElement !== $("balance")) $("balance").value = s.balance;
  for (const k of ["target_fps", "render_scale", "lod_error"]) {
    if (document.activeElement !== $(k)) $(k).value = s[k] == null ? "" : s[k];
  }
  $("scene").hidden = s.scene_time == null;  // a scene that moves: its own time, paused and scrubbed apart
  if (s.scene_time != null) {
    $("scenetime").textContent = s.scene_time.toFixed(2);
    $("scenepause").textContent = s.scene_paused ? "play scene" : "pause scene";
  }
  $("stepof").hidden = s.step == null;  // a simulation's time series: the step on the wall (counted from 1)
  if (s.step != null) {
    $("step").textContent = s.step + 1;
    $("steps").textContent = (seen.header && seen.header.series_steps) || "?";
    $("steplate").hidden = !s.step_late;
    $("stepnote").textContent = s.step_note || "";  // a stream: "waiting for step N", or its end
  }
  $("fly").hidden = !s.interactive;
  $("head").hidden = !s.viewer;
  $("controls").hidden = !!s.view;  // a finished run (multigpu view): nothing to control
}

function addEvent(t, text) {
  const li = document.createElement("li");
  li.textContent = `${new Date(t * 1000).toLocaleTimeString()}  ${text}`;
  $("eventlist").appendChild(li);
}

function showSummary(s) {
  seen.summary = s;
  $("summary").hidden = false;
  const table = $("summarytable");
  table.replaceChildren();
  for (const [k, v] of Object.entries(s)) {
    if (v !== null && typeof v === "object") continue;
    const tr = table.insertRow();
    tr.insertCell().textContent = k;
    tr.insertCell().textContent = typeof v === "number" ? +v.toFixed(4) : String(v);
  }
  $("state").textContent = "run ended";
}

// -- controls
$("pause").onclick = () => send({ do: status.paused ? "resume" : "pause" });
$("stop").onclick = () => send({ do: "stop" });
$("scenepause").onclick = () => send({ do: status.scene_paused ? "scene_play" : "scene_pause" });
$("sceneat").onchange = (e) => { if (e.target.value !== "") send({ do: "scene_time", value: +e.target.value }); };
$("record").onclick = () => send({ do: "record", on: !status.recording });
$("overlay").onchange = () => drawParts(pieces);
$("balance").onchange = (e) => send({ do: "balance", name: e.target.value });
$("target_fps").onchange = (e) => send({ do: "target_fps", value: e.target.value === "" ? null : +e.target.value });
$("render_scale").onchange = (e) => send({ do: "render_scale", value: +e.target.value });
$("lod_error").onchange = (e) => send({ do: "lod_error", value: +e.target.value });
$("orbit").onclick = () => send({ do: "orbit" });
$("reset").onclick = () => send({ do: "reset" });
$("faster").onclick = () => send({ do: "speed", steps: 1 });
$("headhome").onclick = () => send({ do: "head_home" });
for (const b of document.querySelectorAll("#head button[data-head]")) {
  const [dx, dy, dz] = b.dataset.head.split(",").map(Number);
  b.onclick = () => send({ do: "head", dx, dy, dz });
}
$("slower").onclick = () => send({ do: "speed", steps: -1 });

function hold(move, on) {
  const had = held.has(move);
  if (on) held.add(move); else held.delete(move);
  if (had !== on) send({ do: "keys", held: [...held] });
}
for (const b of document.querySelectorAll("#fly button[data-move]")) {
  const move = b.dataset.move;
  b.addEventListener("pointerdown", (e) => { e.preventDefault(); hold(move, true); });
  for (const ev of ["pointerup", "pointerleave", "pointercancel"]) b.addEventListener(ev, () => hold(move, false));
}
const view = $("view");
view.addEventListener("keydown", (e) => {
  const move = MOVES[e.key.toLowerCase()];
  if (move) { e.preventDefault(); hold(move, true); }
});
view.addEventListener("keyup", (e) => { const move = MOVES[e.key.toLowerCase()]; if (move) hold(move, false); });
view.addEventListener("blur", () => { for (const m of [...held]) hold(m, false); });

// drag (mouse or touch) turns the view: pixels of the thumbnail as pixels of the wall
let dragAt = null, pending = [0, 0], flush = null;
view.addEventListener("pointerdown", (e) => { view.focus(); dragAt = [e.clientX, e.clientY]; view.setPointerCapture(e.pointerId); });
view.addEventListener("pointermove", (e) => {
  if (!dragAt) return;
  const k = wallWidth && $("thumb").clientWidth ? wallWidth / $("thumb").clientWidth : 1;
  const clamp = (v) => Math.max(-9999, Math.min(9999, v));
  pending[0] = clamp(pending[0] + (e.clientX - dragAt[0]) * k);
  pending[1] = clamp(pending[1] + (e.clientY - dragAt[1]) * k);
  dragAt = [e.clientX, e.clientY];
  if (!flush) flush = setTimeout(() => {
    send({ do: "drag", dx: pending[0], dy: pending[1] });
    pending = [0, 0]; flush = null;
  }, 50);
});
for (const ev of ["pointerup", "pointercancel"]) view.addEventListener(ev, () => { dragAt = null; });

connect();
