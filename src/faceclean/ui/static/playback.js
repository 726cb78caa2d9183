// Offline playback: the playhead (play.t, s from the take's first frame), played, paused,
// scrubbed or sought; the curves page through the take a window at a time, and each new
// window asks the server for its cleaned part first ({"type": "view", t0, t1}).
import { isOpen, send } from "/channel.js";
import { $, page, play, redraw, span, windowStart } from "/page.js";

export function viewChanged() {
  if (page.hello && page.hello.mode === "offline" && isOpen()) {
    const t0 = windowStart();
    send({ type: "view", t0, t1: t0 + span() });
  }
}

export function seek(t) {
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
export function pause() { play.playing = false; $("fc-play").textContent = "▶ play"; }

export function bindPlayback() {
  $("fc-play").addEventListener("click", () => (play.playing ? pause() : resume()));
  $("fc-scrub").addEventListener("input", () => { pause(); seek((+$("fc-scrub").value / 10000) * play.duration); });
  document.addEventListener("keydown", (e) => {
    if (e.code === "Space" && e.target === document.body && page.hello.mode === "offline") { e.preventDefault(); $("fc-play").click(); }
  });
}
