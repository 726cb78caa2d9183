// One channel's curves on a canvas: the input (grey) and the cleaned output (blue) over
// [t0, t0 + span] s. A series is { count, time(i) s, value(i) } in time order, value NaN
// where missing (the pen lifts there).
export const STYLE = { input: ["#8d949c", 1], cleaned: ["#1f6fd1", 1.8] };

function niceStep(span, count) {
  const raw = span / count, p = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 5, 10].map((k) => k * p).find((s) => s >= raw);
}

// First index whose time is >= t (series times ascending).
function lowerBound(s, t) {
  let lo = 0, hi = s.count;
  while (lo < hi) {
    const mid = (lo + hi) >> 1;
    if (s.time(mid) < t) lo = mid + 1; else hi = mid;
  }
  return lo;
}

export function drawCurve(canvas, series, t0, span, head = null) {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (!w || !h) return;
  const dpr = window.devicePixelRatio || 1;
  if (canvas.width !== Math.round(w * dpr)) canvas.width = Math.round(w * dpr);
  if (canvas.height !== Math.round(h * dpr)) canvas.height = Math.round(h * dpr);
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  const spans = series.map((s) => [Math.max(lowerBound(s, t0) - 1, 0), Math.min(lowerBound(s, t0 + span) + 1, s.count)]);
  let lo = 0, hi = 1;
  series.forEach((s, k) => {
    for (let i = spans[k][0]; i < spans[k][1]; i++) {
      const v = s.value(i);
      if (v < lo) lo = v;
      if (v > hi) hi = v;
    }
  });
  const top = 4, bottom = h - 14;
  const X = (t) => ((t - t0) / span) * w;
  const Y = (v) => bottom - ((v - lo) / (hi - lo || 1)) * (bottom - top);
  ctx.font = "10px system-ui, sans-serif";
  ctx.fillStyle = "#6b7280";
  ctx.strokeStyle = "#eceff3";
  ctx.lineWidth = 1;
  const step = niceStep(span, Math.max(2, Math.floor(w / 90)));
  for (let t = Math.ceil(t0 / step) * step; t <= t0 + span + 1e-9; t += step) {
    ctx.beginPath(); ctx.moveTo(X(t), top); ctx.lineTo(X(t), bottom); ctx.stroke();
    ctx.fillText(`${+t.toFixed(3)} s`, Math.min(X(t) + 2, w - 34), h - 3);
  }
  for (const v of [lo, hi]) { ctx.beginPath(); ctx.moveTo(0, Y(v)); ctx.lineTo(w, Y(v)); ctx.stroke(); }
  ctx.fillText(hi.toFixed(2), 2, top + 9);
  ctx.fillText(lo.toFixed(2), 2, bottom - 2);
  series.forEach((s, k) => {
    ctx.strokeStyle = s.style[0];
    ctx.lineWidth = s.style[1];
    ctx.beginPath();
    let pen = false;
    for (let i = spans[k][0]; i < spans[k][1]; i++) {
      const v = s.value(i);
      if (!Number.isFinite(v)) { pen = false; continue; }
      const x = X(s.time(i)), y = Y(v);
      if (pen) ctx.lineTo(x, y); else ctx.moveTo(x, y);
      pen = true;
    }
    ctx.stroke();
  });
  if (head !== null) {
    ctx.strokeStyle = "#d93025";
    ctx.lineWidth = 1.5;
    ctx.beginPath(); ctx.moveTo(X(head), 0); ctx.lineTo(X(head), h); ctx.stroke();
  }
}
