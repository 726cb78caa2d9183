// The status line under the title: offline, the take and what cleans it; live, the
// relay's or the camera's counters and latencies (the server's "stats").
import { $, api, page, play } from "/page.js";

export function showStatus() {
  const hello = page.hello, state = page.state;
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
