// The plot rows: one canvas per picked channel (curves.js draws it), input and cleaned
// over the window (offline: the page of the take at the playhead; live: the last
// play.span s, at most liveRates().curves a second). Live, the server sends only the
// picked channels' curves ({"type": "channels", names}).
import { isOpen, send, ws } from "/channel.js";
import { drawCurve, STYLE } from "/curves.js";
import { $, api, live, liveRates, page, play, redraw, span, take, throttled, windowStart } from "/page.js";
import { pause, seek, viewChanged } from "/playback.js";

const picked = [];
const plots = new Map(); // channel index -> canvas

export function pick(j) {
  if (j < 0 || plots.has(j)) return;
  picked.push(j);
  const row = document.createElement("div");
  row.className = "plot";
  const name = document.createElement("div");
  name.className = "name";
  name.textContent = page.hello.channels[j];
  const x = document.createElement("button");
  x.type = "button"; x.textContent = "×"; x.title = "remove";
  x.addEventListener("click", () => unpick(j));
  name.append(x);
  const canvas = document.createElement("canvas");
  canvas.addEventListener("pointerdown", (e) => {
    if (page.hello.mode !== "offline") return;
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
  const hello = page.hello;
  if (hello && hello.mode === "live" && isOpen()) {
    send({ type: "channels", names: picked.map((j) => hello.channels[j]) });
  }
}
ws.addEventListener("open", () => channelsChanged());

// The curve pickers: a group's channels at once ("none" clears), a channel, the window.
export function bindPlots() {
  $("fc-group").addEventListener("change", (e) => {
    const g = e.target.value;
    if (g === "-") { while (picked.length) unpick(picked[0]); }
    else if (g) page.hello.groups[g].forEach((c) => pick(page.hello.channels.indexOf(c)));
    e.target.value = "";
  });
  $("fc-channel").addEventListener("change", (e) => { pick(page.hello.channels.indexOf(e.target.value)); e.target.value = ""; });
  $("fc-span").addEventListener("change", (e) => { play.span = +e.target.value; viewChanged(); redraw(); });
}

function takeSeries(arr, j) {
  const t0 = take.times[0];
  return { count: take.n, time: (i) => take.times[i] - t0, value: (i) => arr[i * 52 + j] };
}
function liveSeries(map, j) {
  const v = map.get(j) || [];
  return { count: Math.min(v.length, live.t.length), time: (i) => live.t[i], value: (i) => v[i] };
}

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

export function drawCurves() {
  if (page.hello.mode !== "offline") return liveCurves();
  const t0 = windowStart();
  for (const [j, p] of plots) {
    const series = [
      { ...takeSeries(take.input, j), style: STYLE.input },
      { ...takeSeries(take.cleaned, j), style: STYLE.cleaned },
    ];
    drawCurve(p.canvas, series, t0, span(), play.t);
  }
}
