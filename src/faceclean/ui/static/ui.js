// faceclean tuning page: a thin view over the server (faceclean/ui). Every control is a
// CLI word: the cleaner's words (--method/--preset/--model) and --set items, sent whole
// as {"type": "set", words, items}; the server checks them with the CLI's resolver and
// answers with the state, or the CLI's one-line refusal, shown below the controls.
// Offline: the take arrives as ARKit-52 float32 arrays (binary messages); live: frames
// arrive aggregated, at most ~30 messages a second; on track --camera --ui the camera's
// image arrives as JPEG binary messages (faceclean/ui/camera.py) beside them. The guided
// calibration's panel is guided.js.
import { faceView, softwareGL } from "faceclean/face";
import { drawCurve, STYLE } from "/curves.js";
import { guidedPanel } from "/guided.js";

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const token = params.get("token");
const LIVE_KEEP = 60; // s of live frames kept for the curves
const DEFAULT_CURVES = ["jawOpen", "eyeBlinkLeft", "mouthSmileLeft", "browInnerUp"];
// The live view redraws at most this often (Hz), curves and faces: a screen's worth on a
// GPU; on software GL every draw costs the CPU a relay on the same machine needs (its
// p99 latency), so the faces move 8 times a second and the curves 15 (docs/UI.md).
const LIVE_HZ = { gpu: { curves: 60, faces: 30 }, software: { curves: 15, faces: 8 } };
// Slider ranges of the known smoothing keys: [lo, hi, log scale?] in the key's units.
const RANGES = {
  min_cutoff: [0.01, 50, true], beta: [0.001, 100, true], d_cutoff: [0.1, 30, true],
  tau: [0.001, 2, true], gamma: [0.01, 1, false], q: [0.01, 1000, true], r: [1e-4, 1, true],
  sigma: [0.001, 0.5, true], sigma_frames: [0.1, 50, true],
  detail: [0, 1, false], // the tracker map's: the share of its fitted detail (lag taken back)
};
const LEVELS = { gain: [0, 4, false, 1], offset: [-0.5, 0.5, false, 0], curve: [0.2, 5, true, 1] };

const api = {
  ready: false, mode: null, frames: 0, pushes: 0, openMs: null, readyMs: null, firstFrameMs: null, errors: [], notes: [],
  state: null, sentSeq: 0, setSeq: 0, stats: null, cleanedSeq: null, fullSeq: null, cleanedParts: 0,
  calibrating: null, countdown: [], softwareGL: null, faceDraws: 0, curveDraws: 0, firstFaceMs: null,
  guided: null, guidedPhase: null, guidedShown: [], images: 0, imageSize: null, // the guided panel; camera images drawn
  sentAt: {}, cleanedAt: {}, fullAt: {}, // ms (page clock) a message went, its first cleaned part and whole take came
  get time() { return play.t; },
  get cleaned() { return take.cleaned; }, // (N * 52) float32, offline
  get input() { return take.input; },
  seek: (t) => seek(t),
  send: (m) => send(m),
};
window.faceclean = api;

let hello = null, state = null, items = [], face = null, seq = 0, guided = null;
let inFlight = null, dirty = false; // one "set" at a time; the newest wins
const picked = [];
const play = { t: 0, playing: false, last: null, span: 10, duration: 0 };
const take = { times: null, input: null, cleaned: null, n: 0 };
const live = { t: [], x: new Map(), y: new Map(), fx: null, fy: null, tLast: 0 };

// The face comes beside the live channel (its first message stays small).
const meshLoaded = fetch("/mesh.json").then((r) => r.json());

// ---- the channel ---------------------------------------------------------------------
const ws = new WebSocket(`ws://${location.host}/live${token ? `?token=${encodeURIComponent(token)}` : ""}`);
ws.binaryType = "arraybuffer";
ws.onmessage = (e) => {
  if (typeof e.data !== "string") return onBinary(e.data);
  const m = JSON.parse(e.data);
  if (m.type === "frames" && m.t.length && api.firstFrameMs === null) api.firstFrameMs = e.timeStamp;
  onMessage(m);
};
ws.addEventListener("open", (e) => { api.openMs = e.timeStamp; });
ws.onclose = () => { $("fc-status").textContent = "disconnected: the server stopped (or refused the page)"; };

function send(m) {
  m.seq = ++seq;
  api.sentSeq = seq;
  api.sentAt[seq] = performance.now();
  ws.send(JSON.stringify(m));
  return seq;
}

function note(text, bad = false) {
  const el = $("fc-message");
  el.textContent = text;
  el.classList.toggle("bad", bad);
  (bad ? api.errors : api.notes).push(text);
}

function onMessage(m) {
  if (m.type === "hello") return start(m);
  if (m.type === "state") return onState(m);
  if (m.type === "error") {
    note(m.message, true);
    if (m.for === "set") { inFlight = null; items = state ? [...state.items] : []; render(); flush(); }
    return;
  }
  if (m.type === "frames") { api.pushes++; return onFrames(m); }
  if (m.type === "stats") { api.stats = m; return showStatus(); }
  if (m.type === "calibrating") return onCalibrating(m);
  if (m.type === "guided") return guided && guided.on(m);
  if (m.type === "saved") {
    const rest = m.rest.length ? ` (not in a preset, keep as --set: ${m.rest.join(" ")})` : "";
    return note(`saved ${m.what} ${m.path}${rest}`);
  }
  if (m.type === "exported") return note(`exported ${m.path}`);
  if (m.type === "recording") {
    $("fc-record").textContent = m.on ? "stop recording" : "start recording";
    return note(m.on ? `recording to ${m.path}` : `recorded ${m.frames} frames: ${m.path}`);
  }
}

function onBinary(buf) {
  const n = new DataView(buf).getUint32(0, true);
  const head = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
  if (head.kind === "image") return onImage(head, new Uint8Array(buf, 4 + n, head.bytes));
  const values = new Float32Array(buf, 4 + n, head.count * 52);
  if (head.kind === "input") {
    take.input = new Float32Array(values);
    take.cleaned = take.cleaned || new Float32Array(values);
  } else {
    take.cleaned.set(values, head.start * 52);
    api.cleanedSeq = head.seq;
    api.cleanedAt[head.seq] ??= performance.now();
    if (head.start === 0 && head.count === take.n) {
      api.fullSeq = head.seq ?? 0;
      api.fullAt[head.seq] ??= performance.now();
    }
    api.cleanedParts++;
  }
  api.ready = !!take.input;
  redraw();
}

// ---- start-up ------------------------------------------------------------------------
function start(m) {
  hello = m;
  api.mode = m.mode;
  document.querySelectorAll("[data-mode]").forEach((el) => { el.hidden = el.dataset.mode !== m.mode; });
  $("fc-title").textContent = m.mode === "offline" ? `faceclean tuning: ${m.take}`
    : m.camera ? `faceclean tuning: ${m.camera}` : `faceclean tuning: live relay ${m.relay}`;
  $("fc-camera-box").hidden = !m.camera;
  if (m.guided) guided = guidedPanel(m.guided, send, api);
  document.title = $("fc-title").textContent;
  const words = $("fc-words-list");
  for (const w of ["default", ...m.methods, ...m.presets.map((p) => p)]) words.append(new Option(w, w));
  const tracker = $("fc-tracker");
  for (const t of m.trackers || []) tracker.append(new Option(t, t));
  const scope = $("fc-scope");
  scope.append(new Option("all channels", "*"));
  for (const g of Object.keys(m.groups)) scope.append(new Option(`group: ${g}`, g));
  m.channels.forEach((c) => scope.append(new Option(c, c)));
  const group = $("fc-group");
  group.append(new Option("pick a group…", ""));
  for (const g of Object.keys(m.groups)) group.append(new Option(g, g));
  group.append(new Option("none", "-"));
  const channel = $("fc-channel");
  channel.append(new Option("pick a channel…", ""));
  m.channels.forEach((c) => channel.append(new Option(c, c)));
  DEFAULT_CURVES.forEach((c) => pick(m.channels.indexOf(c)));
  if (m.mode === "offline") {
    take.times = Float64Array.from(m.times);
    take.n = m.times.length;
    play.duration = take.times[take.n - 1];
  } else {
    api.ready = true;
  }
  api.softwareGL = softwareGL();
  // live, on the CPU: the relay may let its browser yield (faceclean/ui/priority.py); said
  // at once, not after the mesh has loaded
  if (m.mode === "live") send({ type: "gl", software: api.softwareGL });
  meshLoaded.then((mesh) => {
    face = faceView($("fc-canvas"), mesh, undefined, { light: api.softwareGL });
    new ResizeObserver(() => { face.fit(); redraw(); }).observe($("fc-canvas"));
    face.fit();
    api.faceReady = true;
    redraw();
  }).catch((err) => note(`The 3D view could not start (${err.message}); the curves still work.`, true));
  onState({ ...m.state, seq: 0 });
  bind();
  showStatus();
  api.readyMs = performance.now(); // ms from the page's start: drawn, the live channel open
}

function onState(s) {
  state = s;
  api.state = s;
  if (inFlight !== null && (s.seq === undefined || s.seq === null || s.seq >= inFlight)) inFlight = null;
  items = [...s.items];
  if (document.activeElement !== $("fc-words")) $("fc-words").value = s.words || "";
  if (s.tracker) $("fc-tracker").value = s.tracker;
  $("fc-source").textContent = `cleaning with ${s.source}`;
  $("fc-command").textContent = s.command;
  const cal = s.calibration;
  const measured = cal && cal.guided
    ? `guided, ${cal.guided.seen.length} of ${cal.guided.seen.length + cal.guided.not_seen.length} prompts seen (tracker ${cal.tracker})`
    : cal && `neutral ${(+cal.neutral_s).toFixed(2)} s`;
  $("fc-calibration").textContent = cal
    ? `calibrated${cal.take ? ` from ${cal.take}` : ""}: ${cal.frames} frames, ${measured}${cal.file ? `; saved as ${cal.file}` : ` (not saved yet: save ${cal.guided ? "calibration" : "levels"})`}`
    : "no calibration";
  render();
  flush();
}

// ---- controls: every change is a --set item -------------------------------------------
function lhsOf(item) { return item.split("=")[0].trim(); }
function scopeKey(key) { const s = $("fc-scope").value; return s === "*" ? key : `${s}.${key}`; }
function itemValue(lhs) {
  const found = items.filter((i) => lhsOf(i) === lhs).pop();
  return found === undefined ? undefined : found.slice(found.indexOf("=") + 1);
}

function setItem(key, text) {
  const lhs = scopeKey(key);
  items = items.filter((i) => lhsOf(i) !== lhs);
  if (text !== null) items.push(text === "" ? lhs : `${lhs}=${text}`);
  $("fc-items").value = items.join("\n");
  requestSet();
}

function requestSet() { dirty = true; flush(); }
function flush() {
  if (!dirty || inFlight !== null || ws.readyState !== WebSocket.OPEN) return;
  dirty = false;
  const words = $("fc-words").value.trim();
  const tracker = $("fc-tracker").value || null;
  inFlight = send({ type: "set", words: words && words !== "default" ? words : null, items, tracker });
  api.setSeq = inFlight;
}

function toSlider(v, [lo, hi, log]) {
  const u = log ? Math.log(v / lo) / Math.log(hi / lo) : (v - lo) / (hi - lo);
  return Math.round(1000 * Math.min(Math.max(u, 0), 1));
}
function fromSlider(s, [lo, hi, log]) {
  const u = s / 1000;
  return log ? lo * (hi / lo) ** u : lo + u * (hi - lo);
}
function fmt(v) { return Math.abs(v) >= 100 ? v.toFixed(0) : +v.toPrecision(3) + ""; }

function slider(holder, key, value, range, onValue) {
  const row = document.createElement("div");
  row.className = "slider";
  const name = document.createElement("label");
  name.textContent = key;
  const input = document.createElement("input");
  input.type = "range"; input.min = "0"; input.max = "1000"; input.step = "1";
  input.id = `fc-${key}`;
  input.dataset.key = key;
  input.value = String(toSlider(value, range));
  const shown = document.createElement("span");
  shown.textContent = fmt(value);
  input.addEventListener("input", () => {
    const v = +fmt(fromSlider(+input.value, range));
    shown.textContent = fmt(v);
    onValue(v);
  });
  row.append(name, input, shown);
  holder.append(row);
}

function scopeChannels() {
  const s = $("fc-scope").value;
  if (s === "*") return hello.channels.map((_, j) => j);
  if (hello.groups[s]) return hello.groups[s].map((c) => hello.channels.indexOf(c));
  return [hello.channels.indexOf(s)];
}

// The controls are built once for a cleaner's keys and scope; a new value only moves its
// slider. (On software GL every layout of the page costs the CPU the server needs, and a
// rebuilt panel delayed the cleaned window a slider click asks for by 5-20 ms.)
let built = null;
function smoothValue(key, cols) {
  const own = itemValue(scopeKey(key));
  return own !== undefined && Number.isFinite(+own) ? +own : state.values[key][cols[0]];
}
function levelValue(key) {
  const own = itemValue(scopeKey(key));
  return own !== undefined ? +own : LEVELS[key][3];
}
function moveSlider(key, value, range) {
  const input = $(`fc-${key}`);
  if (!input || document.activeElement === input) return; // the one in the hand shows its own
  const at = String(toSlider(value, range));
  if (input.value !== at) input.value = at;
  const shown = input.nextElementSibling;
  if (shown.textContent !== fmt(value)) shown.textContent = fmt(value);
}
function render() {
  if (!hello || !state) return;
  if (document.activeElement !== $("fc-items")) $("fc-items").value = items.join("\n");
  const cols = scopeChannels();
  const shape = JSON.stringify([state.method, state.keys.filter((k) => state.values[k]), $("fc-scope").value]);
  if (shape === built) {
    for (const key of state.keys) if (state.values[key]) moveSlider(key, smoothValue(key, cols), RANGES[key] || [1e-3, 1e3, true]);
    for (const [key, range] of Object.entries(LEVELS)) moveSlider(key, levelValue(key), range);
    const clamp = $("fc-clamp"), off = $("fc-off");
    if (document.activeElement !== clamp) clamp.value = itemValue(scopeKey("clamp")) || "";
    off.checked = itemValue(scopeKey("off")) !== undefined;
    return;
  }
  built = shape;
  const smooth = $("fc-smoothing");
  smooth.replaceChildren();
  for (const key of state.keys) {
    if (!state.values[key]) continue;
    slider(smooth, key, smoothValue(key, cols), RANGES[key] || [1e-3, 1e3, true], (x) => setItem(key, String(x)));
  }
  if (!state.keys.length) {
    const p = document.createElement("p");
    p.className = "note";
    p.textContent = `${state.method} has no per-channel smoothing keys; choose one-euro, ema or kalman to smooth by hand`;
    smooth.append(p);
  }
  const levels = $("fc-levels");
  levels.replaceChildren();
  for (const [key, range] of Object.entries(LEVELS)) {
    slider(levels, key, levelValue(key), range, (x) => setItem(key, String(x)));
  }
  const row = document.createElement("div");
  row.className = "row";
  const clampLabel = document.createElement("label");
  clampLabel.textContent = "clamp ";
  const clamp = document.createElement("input");
  clamp.id = "fc-clamp"; clamp.placeholder = "lo,hi"; clamp.size = 8;
  clamp.value = itemValue(scopeKey("clamp")) || "";
  clamp.addEventListener("change", () => setItem("clamp", clamp.value.trim() || null));
  clampLabel.append(clamp);
  const offLabel = document.createElement("label");
  const off = document.createElement("input");
  off.type = "checkbox"; off.id = "fc-off";
  off.checked = itemValue(scopeKey("off")) !== undefined;
  off.addEventListener("change", () => setItem("off", off.checked ? "" : null));
  offLabel.append(off, document.createTextNode(" off"));
  row.append(clampLabel, offLabel);
  levels.append(row);
}

function bind() {
  $("fc-words").addEventListener("change", () => { items = []; requestSet(); });
  $("fc-tracker").addEventListener("change", () => { $("fc-words").value = ""; items = []; requestSet(); });
  $("fc-scope").addEventListener("change", render);
  $("fc-apply").addEventListener("click", () => {
    items = $("fc-items").value.split("\n").map((s) => s.trim()).filter(Boolean);
    requestSet();
  });
  const path = () => $("fc-path").value.trim();
  $("fc-save-preset").addEventListener("click", () => send({ type: "save", what: "preset", path: path() }));
  $("fc-save-levels").addEventListener("click", () => send({ type: "save", what: "levels", path: path() }));
  $("fc-load-preset").addEventListener("click", () => send({ type: "load", what: "preset", path: path() }));
  $("fc-load-levels").addEventListener("click", () => send({ type: "load", what: "levels", path: path() }));
  $("fc-export").addEventListener("click", () => send({ type: "export", path: path() }));
  $("fc-record").addEventListener("click", () => {
    const on = $("fc-record").textContent.startsWith("stop");
    send({ type: "record", action: on ? "stop" : "start", path: path() });
  });
  $("fc-calibrate").addEventListener("click", () => {
    const seconds = +$("fc-hold").value;
    send(hello.mode === "offline" ? { type: "calibrate", seconds, start: play.t } : { type: "calibrate", seconds });
  });
  $("fc-uncalibrate").addEventListener("click", () => send({ type: "uncalibrate" }));
  $("fc-group").addEventListener("change", (e) => {
    const g = e.target.value;
    if (g === "-") { while (picked.length) unpick(picked[0]); }
    else if (g) hello.groups[g].forEach((c) => pick(hello.channels.indexOf(c)));
    e.target.value = "";
  });
  $("fc-channel").addEventListener("change", (e) => { pick(hello.channels.indexOf(e.target.value)); e.target.value = ""; });
  $("fc-span").addEventListener("change", (e) => { play.span = +e.target.value; viewChanged(); redraw(); });
  $("fc-play").addEventListener("click", () => (play.playing ? pause() : resume()));
  $("fc-scrub").addEventListener("input", () => { pause(); seek((+$("fc-scrub").value / 10000) * play.duration); });
  document.addEventListener("keydown", (e) => {
    if (e.code === "Space" && e.target === document.body && hello.mode === "offline") { e.preventDefault(); $("fc-play").click(); }
  });
  if (hello.mode === "offline") viewChanged();
}

// ---- curves ----------------------------------------------------------------------------
const plots = new Map(); // channel index -> canvas

function pick(j) {
  if (j < 0 || plots.has(j)) return;
  picked.push(j);
  const row = document.createElement("div");
  row.className = "plot";
  const name = document.createElement("div");
  name.className = "name";
  name.textContent = hello.channels[j];
  const x = document.createElement("button");
  x.type = "button"; x.textContent = "×"; x.title = "remove";
  x.addEventListener("click", () => unpick(j));
  name.append(x);
  const canvas = document.createElement("canvas");
  canvas.addEventListener("pointerdown", (e) => {
    if (hello.mode !== "offline") return;
    const r = canvas.getBoundingClientRect();
    pause();
    seek(windowStart() + ((e.clientX - r.left) / r.width) * span());
  });
  row.append(name, canvas);
  $("fc-curves").append(row);
  plots.set(j, { canvas, row });
  channelsChanged();
  redraw();
}

function unpick(j) {
  const p = plots.get(j);
  if (!p) return;
  p.row.remove();
  plots.delete(j);
  picked.splice(picked.indexOf(j), 1);
  channelsChanged();
}

function channelsChanged() {
  if (hello && hello.mode === "live" && ws.readyState === WebSocket.OPEN) {
    send({ type: "channels", names: picked.map((j) => hello.channels[j]) });
  }
}
ws.addEventListener("open", () => channelsChanged());

function span() { return hello.mode === "offline" ? Math.min(play.span, play.duration || play.span) : play.span; }
function windowStart() {
  if (span() >= play.duration) return 0;
  return Math.floor(play.t / span()) * span(); // pages of the take
}

function viewChanged() {
  if (hello && hello.mode === "offline" && ws.readyState === WebSocket.OPEN) {
    const t0 = windowStart();
    send({ type: "view", t0, t1: t0 + span() });
  }
}

function takeSeries(arr, j) {
  const t0 = take.times[0];
  return { count: take.n, time: (i) => take.times[i] - t0, value: (i) => arr[i * 52 + j] };
}
function liveSeries(map, j) {
  const v = map.get(j) || [];
  return { count: Math.min(v.length, live.t.length), time: (i) => live.t[i], value: (i) => v[i] };
}

let pending = false;
function redraw() {
  if (pending) return;
  pending = true;
  requestAnimationFrame(() => { pending = false; draw(); });
}

// fn() at most hz() times a second; a call that comes too soon brings a redraw later, so
// the last state always shows.
function throttled(fn, hz) {
  let at = -Infinity, later = null;
  return () => {
    const wait = 1000 / hz() - (performance.now() - at);
    if (wait > 0) {
      if (later === null) later = setTimeout(() => { later = null; redraw(); }, wait);
      return;
    }
    at = performance.now();
    fn();
  };
}
const liveRates = () => LIVE_HZ[api.softwareGL ? "software" : "gpu"];
const liveCurves = throttled(() => {
  const t0 = live.tLast - play.span;
  for (const [j, p] of plots) {
    const series = [
      { ...liveSeries(live.x, j), style: STYLE.input },
      { ...liveSeries(live.y, j), style: STYLE.cleaned },
    ];
    drawCurve(p.canvas, series, t0, play.span);
  }
  api.curveDraws++;
}, () => liveRates().curves);
const liveFaces = throttled(() => {
  face.show([live.fx, live.fy]);
  api.faceDraws++;
  if (api.firstFaceMs === null) api.firstFaceMs = performance.now(); // ms from the page's start
}, () => liveRates().faces);

function draw() {
  if (!hello) return;
  if (hello.mode === "offline") {
    if (!take.input) return;
    const t0 = windowStart();
    for (const [j, p] of plots) {
      const series = [
        { ...takeSeries(take.input, j), style: STYLE.input },
        { ...takeSeries(take.cleaned, j), style: STYLE.cleaned },
      ];
      drawCurve(p.canvas, series, t0, span(), play.t);
    }
    if (face) face.show([weightsAt(take.input), weightsAt(take.cleaned)]);
  } else {
    liveCurves();
    if (face && live.fx) liveFaces();
  }
}

// (52,) weights of a take array at the playhead; a missing frame holds the last valid one.
function weightsAt(arr) {
  const t = play.t + take.times[0];
  let lo = 0, hi = take.n - 1;
  while (lo < hi) { const mid = (lo + hi + 1) >> 1; if (take.times[mid] <= t) lo = mid; else hi = mid - 1; }
  let i = lo;
  while (i > 0 && !Number.isFinite(arr[i * 52])) i--;
  const w = new Array(52);
  for (let j = 0; j < 52; j++) { const v = arr[i * 52 + j]; w[j] = Number.isFinite(v) ? v : 0; }
  return w;
}

// ---- offline playback ------------------------------------------------------------------
function seek(t) {
  const before = windowStart();
  play.t = Math.min(Math.max(+t || 0, 0), play.duration);
  $("fc-scrub").value = String(Math.round((play.t / (play.duration || 1)) * 10000));
  $("fc-time").textContent = `${play.t.toFixed(2)} / ${play.duration.toFixed(2)} s`;
  if (windowStart() !== before) viewChanged();
  redraw();
}
function tick(now) {
  if (!play.playing) return;
  if (play.last !== null) {
    let t = play.t + (now - play.last) / 1000;
    if (t > play.duration) t = 0;
    seek(t);
  }
  play.last = now;
  requestAnimationFrame(tick);
}
function resume() { play.playing = true; play.last = null; $("fc-play").textContent = "❚❚ pause"; requestAnimationFrame(tick); }
function pause() { play.playing = false; $("fc-play").textContent = "▶ play"; }

// ---- live --------------------------------------------------------------------------------
function onFrames(m) {
  api.frames += m.t.length;
  if (m.restart) { live.t = []; live.x.clear(); live.y.clear(); }
  m.channels.forEach((j, k) => {
    if (!live.x.has(j) || live.x.get(j).length !== live.t.length) {
      live.x.set(j, new Array(live.t.length).fill(NaN));
      live.y.set(j, new Array(live.t.length).fill(NaN));
    }
  });
  for (const j of live.x.keys()) {
    if (!m.channels.includes(j)) { live.x.delete(j); live.y.delete(j); }
  }
  for (let i = 0; i < m.t.length; i++) {
    live.t.push(m.t[i]);
    m.channels.forEach((j, k) => {
      live.x.get(j).push(m.x[i][k] === null ? NaN : m.x[i][k]);
      live.y.get(j).push(m.y[i][k] === null ? NaN : m.y[i][k]);
    });
  }
  if (m.t.length) live.tLast = m.t[m.t.length - 1];
  let cut = 0;
  while (cut < live.t.length && live.t[cut] < live.tLast - LIVE_KEEP) cut++;
  if (cut > 0) {
    live.t.splice(0, cut);
    for (const v of live.x.values()) v.splice(0, cut);
    for (const v of live.y.values()) v.splice(0, cut);
  }
  if (m.fx) { live.fx = m.fx.map((v) => v ?? 0); live.fy = m.fy.map((v) => v ?? 0); }
  if (m.stats) api.stats = m.stats;
  showStatus();
  redraw();
}

// A camera image (JPEG): decoded off the main thread, drawn at its own size (CSS fits it).
function onImage(head, jpeg) {
  createImageBitmap(new Blob([jpeg], { type: "image/jpeg" })).then((bitmap) => {
    const canvas = $("fc-camera");
    if (canvas.width !== bitmap.width || canvas.height !== bitmap.height) {
      canvas.width = bitmap.width;
      canvas.height = bitmap.height;
    }
    canvas.getContext("2d").drawImage(bitmap, 0, 0);
    bitmap.close();
    api.images++;
    api.imageSize = [head.width, head.height];
  }).catch((err) => note(`a camera image could not be decoded (${err.message})`, true));
}

function onCalibrating(m) {
  api.calibrating = m;
  const el = $("fc-countdown");
  el.hidden = m.remaining <= 0;
  el.textContent = m.remaining > 0 ? `hold a neutral face… ${m.remaining.toFixed(1)} s` : "";
  if (m.remaining > 0) api.countdown.push(el.textContent);
}

function showStatus() {
  if (!hello) return;
  if (hello.mode === "offline") {
    const s = state ? ` · cleaned with ${state.source}` : "";
    $("fc-status").textContent = `${hello.take} · ${hello.frames} frames (${hello.missing} missing) · ${play.duration.toFixed(2)} s · ${hello.rate.toFixed(1)} fps${s}`;
    return;
  }
  const s = api.stats;
  if (!s) { $("fc-status").textContent = `${hello.relay} · waiting for a sender`; return; }
  const ms = (v) => (v === null ? "–" : `${v.toFixed(3)} ms`);
  if (s.camera) {
    $("fc-status").textContent =
      `${s.camera} · ${s.rate.toFixed(1)} fps · captured ${s.captured} · dropped ${s.dropped} · tracked ${s.tracked} ` +
      `(no face ${s.lost}) · sent ${s.sent} · MediaPipe p50 ${ms(s.mediapipe_p50)} · clean+send p50 ${ms(s.p50)} p99 ${ms(s.p99)}`;
    return;
  }
  $("fc-status").textContent =
    `sender ${s.sender || "none yet"} · ${s.rate.toFixed(1)} fps · in ${s.frames_in} out ${s.frames_out} · ` +
    `dropped ${s.dropped} · latency p50 ${ms(s.p50)} p99 ${ms(s.p99)}`;
}
