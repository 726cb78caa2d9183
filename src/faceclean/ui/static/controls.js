// The cleaner's controls. Every change is a CLI word: the cleaner's words
// (--method/--preset/--model), the tracker, and --set items, sent whole as
// {"type": "set", words, items, tracker}, one at a time (the newest wins); the server
// answers with the state (onState) or the CLI's one-line refusal (refused). Also the
// files (save/load a preset or levels, export the take, record live) and Calibrate.
import { isOpen, send } from "/channel.js";
import { $, api, page, play } from "/page.js";
import { LEVELS, moveSlider, OTHER, RANGES, slider } from "/sliders.js";

// What the controls show: the server's items with the edits it has not answered yet on
// top, so a state that comes while the user is still changing things never takes a
// change back: `sent` went in the "set" in flight (seq inFlight), `queued` came since and
// go, whole, once it is answered. With nothing pending the server's state is what shows.
let items = [];
let inFlight = null, sent = [], queued = [];
const replay = (base, edits) => edits.reduce((its, edit) => edit(its), [...base]);

export function onState(s) {
  page.state = s;
  api.state = s;
  if (inFlight !== null && (s.seq === undefined || s.seq === null || s.seq >= inFlight)) {
    inFlight = null;
    sent = [];
  }
  items = replay(s.items, [...sent, ...queued]);
  if (inFlight === null && !queued.length) showChoice(s);
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

// The cleaner's words and tracker as the server holds them (not while the user types).
function showChoice(s) {
  if (document.activeElement !== $("fc-words")) $("fc-words").value = s.words || "";
  if (s.tracker) $("fc-tracker").value = s.tracker;
}

// The server refused "set" seq (none said: the one in flight): its edits go, the controls
// show the state the server holds with the edits made since on top (they go next). An
// older one (offline, the whole take refused it later) is followed by its state, if any.
export function refused(seq) {
  if (inFlight === null || (seq !== undefined && seq !== null && seq !== inFlight)) return;
  inFlight = null;
  sent = [];
  items = replay(page.state ? page.state.items : [], queued);
  if (!queued.length && page.state) showChoice(page.state);
  render();
  flush();
}

function lhsOf(item) { return item.split("=")[0].trim(); }
function scopeKey(key) { const s = $("fc-scope").value; return s === "*" ? key : `${s}.${key}`; }
function itemValue(lhs) {
  const found = items.filter((i) => lhsOf(i) === lhs).pop();
  return found === undefined ? undefined : found.slice(found.indexOf("=") + 1);
}

function setItem(key, text) {
  const lhs = scopeKey(key), item = text === "" ? lhs : `${lhs}=${text}`;
  edit((its) => [...its.filter((i) => lhsOf(i) !== lhs), ...(text === null ? [] : [item])]);
}

// A change of the items (its(items) -> items): shown at once, sent with the next "set".
function edit(change) {
  items = change(items);
  queued.push(change);
  $("fc-items").value = items.join("\n");
  flush();
}
function flush() {
  if (!queued.length || inFlight !== null || !isOpen()) return;
  [sent, queued] = [queued, []];
  const words = $("fc-words").value.trim();
  const tracker = $("fc-tracker").value || null;
  inFlight = send({ type: "set", words: words && words !== "default" ? words : null, items, tracker });
  api.setSeq = inFlight;
}

function scopeChannels() {
  const hello = page.hello, s = $("fc-scope").value;
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
  return own !== undefined && Number.isFinite(+own) ? +own : page.state.values[key][cols[0]];
}
function levelValue(key) {
  const own = itemValue(scopeKey(key));
  return own !== undefined ? +own : LEVELS[key][3];
}
function render() {
  const state = page.state;
  if (!page.hello || !state) return;
  if (document.activeElement !== $("fc-items")) $("fc-items").value = items.join("\n");
  const cols = scopeChannels();
  const shape = JSON.stringify([state.method, state.keys.filter((k) => state.values[k]), $("fc-scope").value]);
  if (shape === built) {
    for (const key of state.keys) if (state.values[key]) moveSlider(key, smoothValue(key, cols), RANGES[key] || OTHER);
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
    slider(smooth, key, smoothValue(key, cols), RANGES[key] || OTHER, (x) => setItem(key, String(x)));
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

export function bindControls() {
  $("fc-words").addEventListener("change", () => edit(() => []));
  $("fc-tracker").addEventListener("change", () => { $("fc-words").value = ""; edit(() => []); });
  $("fc-scope").addEventListener("change", render);
  $("fc-apply").addEventListener("click", () => {
    const typed = $("fc-items").value.split("\n").map((s) => s.trim()).filter(Boolean);
    edit(() => typed);
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
    send(page.hello.mode === "offline" ? { type: "calibrate", seconds, start: play.t } : { type: "calibrate", seconds });
  });
  $("fc-uncalibrate").addEventListener("click", () => send({ type: "uncalibrate" }));
}

// Calibrate's countdown over the faces, while the server holds the neutral face.
export function onCalibrating(m) {
  api.calibrating = m;
  const el = $("fc-countdown");
  el.hidden = m.remaining <= 0;
  el.textContent = m.remaining > 0 ? `hold a neutral face… ${m.remaining.toFixed(1)} s` : "";
  if (m.remaining > 0) api.countdown.push(el.textContent);
}
