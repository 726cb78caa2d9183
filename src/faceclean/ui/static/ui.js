// faceclean tuning page: a thin view over the server (faceclean/ui). Every control is a
// CLI word: the cleaner's words (--method/--preset/--model) and --set items, sent whole
// as {"type": "set", words, items}; the server checks them with the CLI's resolver and
// answers with the state, or the CLI's one-line refusal, shown below the controls.
// Offline: the take arrives as ARKit-52 float32 arrays (binary messages); live: frames
// arrive aggregated, at most ~30 messages a second; on track --camera --ui the camera's
// image arrives as JPEG binary messages (faceclean/ui/camera.py) beside them.
// This module reads the channel and starts the page; one module a part: page.js (what
// the parts share), channel.js (the WebSocket), controls.js + sliders.js (the cleaner's
// controls), plots.js + curves.js (the curves), faces.js (the 3D faces), playback.js
// (offline playback), live.js (live frames, the camera's image), status.js (the status
// line), guided.js (the guided calibration's panel).
import { detectGL, drawFaces, startFaces } from "/faces.js";
import { send, ws } from "/channel.js";
import { bindControls, onCalibrating, onState, refused } from "/controls.js";
import { guidedPanel } from "/guided.js";
import { onFrames, onImage } from "/live.js";
import { $, api, drawWith, note, page, play, redraw, take } from "/page.js";
import { bindPlayback, seek, viewChanged } from "/playback.js";
import { bindPlots, drawCurves, pick } from "/plots.js";
import { showStatus } from "/status.js";

const DEFAULT_CURVES = ["jawOpen", "eyeBlinkLeft", "mouthSmileLeft", "browInnerUp"];
api.seek = (t) => seek(t);
api.send = (m) => send(m);
let guided = null;

ws.onmessage = (e) => {
  if (typeof e.data !== "string") return onBinary(e.data);
  const m = JSON.parse(e.data);
  if (m.type === "frames" && m.t.length && api.firstFrameMs === null) api.firstFrameMs = e.timeStamp;
  onMessage(m);
};

// A file the page wrote over is said, never replaced in silence.
const over = (m) => (m.replaced ? " (replacing the file that was there)" : "");

function onMessage(m) {
  if (m.type === "hello") return start(m);
  if (m.type === "state") return onState(m);
  if (m.type === "error") {
    note(m.message, true);
    if (m.for === "set") refused(m.seq);
    return;
  }
  if (m.type === "frames") { api.pushes++; return onFrames(m); }
  if (m.type === "stats") { api.stats = m; return showStatus(); }
  if (m.type === "calibrating") return onCalibrating(m);
  if (m.type === "guided") return guided && guided.on(m);
  if (m.type === "saved") {
    const rest = m.rest.length ? ` (not in a preset, keep as --set: ${m.rest.join(" ")})` : "";
    return note(`saved ${m.what} ${m.path}${rest}${over(m)}`);
  }
  if (m.type === "exported") return note(`exported ${m.path}${over(m)}`);
  if (m.type === "recording") {
    $("fc-record").textContent = m.on ? "stop recording" : "start recording";
    const over = m.replaces ? ` (replacing ${m.replaces}${m.on ? " when it stops" : ""})` : "";
    return note((m.on ? `recording to ${m.path}` : `recorded ${m.frames} frames: ${m.path}`) + over);
  }
}

// Offline: the take's input, then its cleaned output in parts (the window asked first).
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

function start(m) {
  page.hello = m;
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
  detectGL();
  // live, on the CPU: the relay may let its browser yield (faceclean/ui/priority.py); said
  // at once, not after the mesh has loaded
  if (m.mode === "live") send({ type: "gl", software: api.softwareGL });
  startFaces();
  onState({ ...m.state, seq: 0 });
  bindControls();
  bindPlots();
  bindPlayback();
  if (m.mode === "offline") viewChanged();
  showStatus();
  api.readyMs = performance.now(); // ms from the page's start: drawn, the live channel open
}

drawWith(() => {
  if (!page.hello) return;
  if (page.hello.mode === "offline" && !take.input) return;
  drawCurves();
  drawFaces();
});
