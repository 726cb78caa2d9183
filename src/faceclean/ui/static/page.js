// What the page's modules share: the element lookup, the test hooks (window.faceclean),
// the server's hello and state, the face view, the take (offline), the playhead and the
// live buffers; the one-line message under the controls; one redraw per animation frame.
export const $ = (id) => document.getElementById(id);
// The live view redraws at most this often (Hz), curves and faces: a screen's worth on a
// GPU; on software GL every draw costs the CPU a relay on the same machine needs (its
// p99 latency), so the faces move 8 times a second and the curves 15 (docs/UI.md).
const LIVE_HZ = { gpu: { curves: 60, faces: 30 }, software: { curves: 15, faces: 8 } };

// hello: the server's first message; state: its newest "state"; face: the 3D view, once
// the mesh has loaded.
export const page = { hello: null, state: null, face: null };
export const play = { t: 0, playing: false, last: null, span: 10, duration: 0 };
export const take = { times: null, input: null, cleaned: null, n: 0 };
export const live = { t: [], x: new Map(), y: new Map(), fx: null, fy: null, tLast: 0 };

// seek and send: set by ui.js (playback.js, channel.js).
export const api = {
  ready: false, mode: null, frames: 0, pushes: 0, openMs: null, readyMs: null, firstFrameMs: null, errors: [], notes: [],
  state: null, sentSeq: 0, setSeq: 0, stats: null, cleanedSeq: null, fullSeq: null, cleanedParts: 0,
  calibrating: null, countdown: [], softwareGL: null, faceDraws: 0, curveDraws: 0, firstFaceMs: null,
  guided: null, guidedPhase: null, guidedShown: [], images: 0, imageSize: null, // the guided panel; camera images drawn
  sentAt: {}, cleanedAt: {}, fullAt: {}, // ms (page clock) a message went, its first cleaned part and whole take came
  get time() { return play.t; },
  get cleaned() { return take.cleaned; }, // (N * 52) float32, offline
  get input() { return take.input; },
  seek: null,
  send: null,
};
window.faceclean = api;

export function note(text, bad = false) {
  const el = $("fc-message");
  el.textContent = text;
  el.classList.toggle("bad", bad);
  (bad ? api.errors : api.notes).push(text);
}

// s shown in the curves: offline the window pages the take (no longer than it).
export function span() { return page.hello.mode === "offline" ? Math.min(play.span, play.duration || play.span) : play.span; }
export function windowStart() {
  if (span() >= play.duration) return 0;
  return Math.floor(play.t / span()) * span(); // pages of the take
}

let draw = () => {};
let pending = false;
// draw(): what redraw() runs, once per animation frame (ui.js sets it).
export function drawWith(fn) { draw = fn; }
export function redraw() {
  if (pending) return;
  pending = true;
  requestAnimationFrame(() => { pending = false; draw(); });
}

// fn() at most hz() times a second; a call that comes too soon brings a redraw later, so
// the last state always shows.
export function throttled(fn, hz) {
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
export const liveRates = () => LIVE_HZ[api.softwareGL ? "software" : "gpu"];
