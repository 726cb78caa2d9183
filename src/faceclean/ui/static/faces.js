// The two faces, input and cleaned, side by side (the report's face view, report/face.js):
// offline at the playhead, live at the newest frame (at most liveRates().faces a second).
import { faceView, softwareGL } from "faceclean/face";
import { $, api, live, note, page, play, redraw, take, throttled, liveRates } from "/page.js";

// The face comes beside the live channel (its first message stays small).
const meshLoaded = fetch("/mesh.json").then((r) => r.json());

// Whether the page draws on software GL (said to the server at hello, before the mesh).
export function detectGL() { api.softwareGL = softwareGL(); }

export function startFaces() {
  meshLoaded.then((mesh) => {
    const face = faceView($("fc-canvas"), mesh, undefined, { light: api.softwareGL });
    page.face = face;
    new ResizeObserver(() => { face.fit(); redraw(); }).observe($("fc-canvas"));
    face.fit();
    api.faceReady = true;
    redraw();
  }).catch((err) => note(`The 3D view could not start (${err.message}); the curves still work.`, true));
}

const liveFaces = throttled(() => {
  page.face.show([live.fx, live.fy]);
  api.faceDraws++;
  if (api.firstFaceMs === null) api.firstFaceMs = performance.now(); // ms from the page's start
}, () => liveRates().faces);

export function drawFaces() {
  if (page.hello.mode === "offline") {
    if (page.face) page.face.show([weightsAt(take.input), weightsAt(take.cleaned)]);
  } else if (page.face && live.fx) {
    liveFaces();
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
