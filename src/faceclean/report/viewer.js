// faceclean report viewer: two faces (input, cleaned) played in sync, and the curves.
// Reads the JSON in #fc-data (written by faceclean/report/build.py); three.js and
// report/face.js (the face view) are inlined into the page through the import map. Times
// in seconds; weights stored as round(value * data.scale) integers, null where missing.
import { faceView } from "faceclean/face";

const data = JSON.parse(document.getElementById("fc-data").textContent);
const times = data.times; // (N,) s from the first frame
const N = times.length;
const duration = times[N - 1];
const COLORS = { input: "#8d949c", truth: "#111111" };
const OTHER = ["#1f6fd1", "#e8710a", "#2ca02c", "#9334e6", "#d62728", "#8c564b", "#e52592"];

const state = { t: 0, playing: false, speed: 1, last: null, w0: 0, span: duration };
const api = {
  ready: false, seek, play, pause, duration,
  get time() { return state.t; },
  get renders() { return view.face ? view.face.renders : 0; },
  // each face's head rotation now, as a quaternion [x, y, z, w] (identity without angles)
  get heads() { return view.face ? view.face.heads : []; },
};
window.faceclean = api;

// Largest i with times[i] <= t (0 before the start).
function frameAt(t) {
  let lo = 0, hi = N - 1;
  if (t <= times[0]) return 0;
  if (t >= times[hi]) return hi;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (times[mid] <= t) lo = mid; else hi = mid;
  }
  return lo;
}

// Value of channel column `col` of series `s` at time t: linear between frames; a
// missing value takes the nearest earlier valid one (the face holds through a gap).
function valueAt(s, col, t) {
  const v = s.values[col];
  if (!v) return 0;
  let i = frameAt(t);
  const a = v[i], b = i + 1 < N ? v[i + 1] : null;
  if (a !== null && b !== null) {
    const u = (t - times[i]) / Math.max(times[i + 1] - times[i], 1e-9);
    return (a + (b - a) * Math.min(Math.max(u, 0), 1)) / data.scale;
  }
  while (i >= 0 && v[i] === null) i--;
  return i >= 0 ? v[i] / data.scale : 0;
}

// A series' head [yaw, pitch, roll] rad at time t (series.head: three lists, null where
// missing; linear, holding through a gap), or null when it has no head angles.
function headAt(s, t) {
  if (!s.head) return null;
  return s.head.map((a) => {
    let i = frameAt(t);
    const x = a[i], y = i + 1 < N ? a[i + 1] : null;
    if (x !== null && y !== null) {
      const u = (t - times[i]) / Math.max(times[i + 1] - times[i], 1e-9);
      return x + (y - x) * Math.min(Math.max(u, 0), 1);
    }
    while (i >= 0 && a[i] === null) i--;
    return i >= 0 ? a[i] : 0;
  });
}

// ---- the 3D view (report/face.js, shared with the tuning page) ----------------------
const view = { face: null };

function setupView() {
  const canvas = document.getElementById("fc-canvas");
  view.face = faceView(canvas, data.mesh);
  view.fit = () => { view.face.fit(); render(); };
  new ResizeObserver(() => view.fit()).observe(canvas);
}

function faceWeights(s, t) {
  const w = new Array(52).fill(0);
  data.arkit.forEach((j, col) => { if (j >= 0) w[j] = valueAt(s, col, t); });
  return w;
}

function render() {
  if (!view.face) return;
  const heads = data.face.map((k) => headAt(data.series[k], state.t));
  view.face.show(data.face.map((k) => faceWeights(data.series[k], state.t)), heads);
}

// ---- curves -------------------------------------------------------------------------
const plots = [];

function seriesStyle(s, k) {
  if (s.kind === "input") return { color: COLORS.input, width: 1, dash: [] };
  if (s.kind === "truth") return { color: COLORS.truth, width: 1.2, dash: [5, 3] };
  return { color: OTHER[k % OTHER.length], width: k === 0 ? 1.8 : 1.3, dash: [] };
}

function setupCurves() {
  const legend = document.getElementById("fc-legend");
  let outK = 0;
  data.series.forEach((s) => {
    s.style = seriesStyle(s, s.kind === "output" ? outK++ : 0);
    const item = document.createElement("span");
    item.className = "key";
    const swatch = document.createElement("i");
    swatch.style.borderTop = `${s.kind === "truth" ? "2px dashed" : "3px solid"} ${s.style.color}`;
    item.append(swatch, document.createTextNode(s.label));
    legend.append(item);
  });
  const outputs = data.series.filter((s) => s.kind === "output");
  data.drawOrder = [...data.series.filter((s) => s.kind !== "output"), ...outputs.slice(1), outputs[0]];
  const zoom = document.getElementById("fc-zoom");
  for (const span of [30, 10, 4]) {
    if (span < duration) zoom.add(new Option(`${span} s`, String(span)));
  }
  zoom.addEventListener("change", () => {
    state.span = Math.min(Number(zoom.value) || duration, duration);
    follow(true);
    plots.forEach(placeHead);
  });
  const root = document.getElementById("fc-groups");
  for (const g of data.groups) {
    const section = document.createElement("section");
    section.className = "group";
    const h = document.createElement("h3");
    h.textContent = g.title;
    section.append(h);
    let holder = section;
    g.channels.forEach((col, k) => {
      if (k === data.open_per_group) {
        const more = document.createElement("details");
        const summary = document.createElement("summary");
        summary.textContent = `${g.channels.length - k} more ${g.title} channels`;
        more.append(summary);
        more.addEventListener("toggle", () => plots.forEach(drawPlot));
        section.append(more);
        holder = more;
      }
      holder.append(makePlot(col));
    });
    root.append(section);
  }
  new ResizeObserver(() => plots.forEach(drawPlot)).observe(root);
}

function makePlot(col) {
  const row = document.createElement("div");
  row.className = "plot";
  const label = document.createElement("div");
  label.className = "name";
  label.textContent = data.channels[col];
  const change = document.createElement("small");
  change.textContent = `changed ${data.change[col].toFixed(3)}`;
  label.append(document.createElement("br"), change);
  const box = document.createElement("div");
  box.className = "box";
  const canvas = document.createElement("canvas");
  const head = document.createElement("div");
  head.className = "playhead";
  box.append(canvas, head);
  row.append(label, box);
  const plot = { col, canvas, head, box };
  plots.push(plot);
  const seekFrom = (e) => {
    const r = canvas.getBoundingClientRect();
    seek(state.w0 + ((e.clientX - r.left) / r.width) * state.span);
  };
  canvas.addEventListener("pointerdown", (e) => { seekFrom(e); canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointermove", (e) => { if (e.buttons) seekFrom(e); });
  return row;
}

function niceStep(span, count) {
  const raw = span / count, p = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 5, 10].map((k) => k * p).find((s) => s >= raw);
}

// Value range of a channel over every series (fixed, so pages of a long clip compare).
function range(col) {
  let lo = 0, hi = 0;
  for (const s of data.series) {
    for (const v of s.values[col] || []) {
      if (v !== null) { lo = Math.min(lo, v / data.scale); hi = Math.max(hi, v / data.scale); }
    }
  }
  return [lo, Math.max(hi * 1.05, lo + 0.05)];
}

function drawPlot(plot) {
  const { canvas, col } = plot;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (!w || !h) return;
  const dpr = window.devicePixelRatio || 1;
  canvas.width = Math.round(w * dpr);
  canvas.height = Math.round(h * dpr);
  const ctx = canvas.getContext("2d");
  ctx.scale(dpr, dpr);
  plot.range = plot.range || range(col);
  const [lo, hi] = plot.range;
  const [t0, span] = [state.w0, state.span];
  const top = 4, bottom = h - 14;
  const X = (t) => ((t - t0) / span) * w;
  const Y = (v) => bottom - ((v - lo) / (hi - lo)) * (bottom - top);
  ctx.font = "10px system-ui, sans-serif";
  ctx.fillStyle = "#6b7280";
  ctx.strokeStyle = "#eceff3";
  const step = niceStep(span, Math.max(2, Math.floor(w / 90)));
  for (let t = Math.ceil(t0 / step) * step; t <= t0 + span + 1e-9; t += step) {
    ctx.beginPath(); ctx.moveTo(X(t), top); ctx.lineTo(X(t), bottom); ctx.stroke();
    ctx.fillText(`${+t.toFixed(3)} s`, Math.min(X(t) + 2, w - 34), h - 3);
  }
  for (const v of [lo, hi]) {
    ctx.beginPath(); ctx.moveTo(0, Y(v)); ctx.lineTo(w, Y(v)); ctx.stroke();
  }
  ctx.fillText(hi.toFixed(2), 2, top + 9);
  ctx.fillText(lo.toFixed(2), 2, bottom - 2);
  const first = Math.max(frameAt(t0) - 1, 0), last = Math.min(frameAt(t0 + span) + 2, N);
  for (const s of data.drawOrder) {
    const v = s.values[col];
    if (!v) continue;
    ctx.strokeStyle = s.style.color;
    ctx.lineWidth = s.style.width;
    ctx.setLineDash(s.style.dash);
    ctx.beginPath();
    let pen = false;
    for (let i = first; i < last; i++) {
      if (v[i] === null) { pen = false; continue; }
      const x = X(times[i]), y = Y(v[i] / data.scale);
      if (pen) ctx.lineTo(x, y); else ctx.moveTo(x, y);
      pen = true;
    }
    ctx.stroke();
  }
  ctx.setLineDash([]);
  placeHead(plot);
}

function placeHead(plot) {
  const u = (state.t - state.w0) / state.span;
  plot.head.style.left = `${u * plot.box.clientWidth}px`;
  plot.head.hidden = u < 0 || u > 1;
}

// The curves show [w0, w0 + span]; when the playhead leaves it, the next page shows.
function follow(force = false) {
  const w0 = state.span >= duration ? 0 : state.w0;
  const outside = state.t < w0 || state.t > w0 + state.span;
  if (!force && !outside && w0 === state.w0) return;
  state.w0 = outside ? Math.min(Math.max(state.t - 0.05 * state.span, 0), duration - state.span) : w0;
  plots.forEach(drawPlot);
}

// ---- playback -----------------------------------------------------------------------
const playButton = document.getElementById("fc-play");
const scrub = document.getElementById("fc-scrub");
const clock = document.getElementById("fc-time");

function seek(t) {
  state.t = Math.min(Math.max(Number(t) || 0, 0), duration);
  scrub.value = String(Math.round((state.t / duration) * Number(scrub.max)));
  clock.textContent = `${state.t.toFixed(2)} / ${duration.toFixed(2)} s`;
  follow();
  plots.forEach(placeHead);
  render();
}

function tick(now) {
  if (!state.playing) return;
  if (state.last !== null) {
    let t = state.t + ((now - state.last) / 1000) * state.speed;
    if (t > duration) t = 0; // loop
    seek(t);
  }
  state.last = now;
  requestAnimationFrame(tick);
}

function play() {
  if (state.playing) return;
  state.playing = true;
  state.last = null;
  playButton.textContent = "❚❚ pause";
  requestAnimationFrame(tick);
}

function pause() {
  state.playing = false;
  playButton.textContent = "▶ play";
}

playButton.addEventListener("click", () => (state.playing ? pause() : play()));
scrub.addEventListener("input", () => { pause(); seek((Number(scrub.value) / Number(scrub.max)) * duration); });
document.getElementById("fc-speed").addEventListener("change", (e) => { state.speed = Number(e.target.value); });
document.addEventListener("keydown", (e) => {
  if (e.code === "Space" && e.target === document.body) { e.preventDefault(); playButton.click(); }
});

setupCurves();
try {
  setupView();
  view.fit();
} catch (err) {
  const note = document.getElementById("fc-noview");
  note.hidden = false;
  note.textContent = `The 3D view could not start (${err.message}); the curves below still work.`;
  console.warn(err);
}
plots.forEach(drawPlot);
seek(0);
api.ready = true;
