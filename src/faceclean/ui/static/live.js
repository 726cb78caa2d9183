// Live: the frames the server aggregates (at most ~30 messages a second), kept for the
// last LIVE_KEEP s of the picked channels' curves, with the newest faces; on track
// --camera --ui, the camera's image (JPEG binary messages, faceclean/ui/camera.py).
import { $, api, live, note, redraw } from "/page.js";
import { showStatus } from "/status.js";

const LIVE_KEEP = 60; // s of live frames kept for the curves

export function onFrames(m) {
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
export function onImage(head, jpeg) {
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
