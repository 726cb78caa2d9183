// The guided calibration's panel (faceclean/ui/guided.py). Live: Start counts down, then
// the server records while each prompt of the script shows here (and over the faces) with
// the seconds it has left; offline: the take is the performance. Then what the fit found:
// per prompt, seen or why not, its channels' peak before -> after (the aim); per channel,
// what the calibration changes. Applied at once unless the take fell short of the script
// ("apply anyway"); undo puts the calibration before back; save writes calibrate --guided's file.
const $ = (id) => document.getElementById(id);
const SHOWN_CHANNELS = 12; // the largest changes listed
const f2 = (v) => (v === null || v === undefined ? "–" : (+v).toFixed(2));

// script: hello's "guided"; send(m) -> seq; api: window.faceclean (test hooks).
export function guidedPanel(script, send, api) {
  const rows = new Map(); // prompt id -> { row, state, peak }
  const table = $("fc-guided-prompts");
  heading(table, ["at", "prompt", "", "peak before → after (aim)"]);
  heading($("fc-guided-channels"), ["channel", "what the calibration changes"]);
  const body = table.createTBody();
  for (const p of script.prompts) {
    const row = body.insertRow();
    row.insertCell().textContent = `${p.start.toFixed(1)} s`;
    row.insertCell().textContent = p.text;
    const state = row.insertCell();
    const peak = row.insertCell();
    rows.set(p.id, { row, state, peak });
  }
  $("fc-guided-about").textContent = script.live
    ? `${script.prompts.length} prompts, ${script.seconds.toFixed(0)} s after a ${script.countdown} s countdown: do each as it shows`
    : `fit on this take, as a performance of the script (${script.prompts.length} prompts, ${script.seconds.toFixed(0)} s)`;
  $("fc-guided-start").textContent = script.live ? "start" : "fit this take";
  $("fc-guided-start").addEventListener("click", () => send({ type: "guided", action: "start" }));
  $("fc-guided-stop").addEventListener("click", () => send({ type: "guided", action: "stop" }));
  $("fc-guided-apply").addEventListener("click", () => send({ type: "guided", action: "apply" }));
  $("fc-guided-undo").addEventListener("click", () => send({ type: "guided", action: "undo" }));
  $("fc-guided-save").addEventListener("click", () => send({ type: "guided", action: "save", path: $("fc-guided-path").value.trim() }));
  buttons("idle");

  function heading(t, names) {
    const row = t.createTHead().insertRow();
    for (const n of names) row.append(Object.assign(document.createElement("th"), { textContent: n }));
  }

  function buttons(phase, done = null) {
    const busy = phase === "countdown" || phase === "recording" || phase === "fitting";
    $("fc-guided-start").disabled = busy;
    $("fc-guided-stop").hidden = !(phase === "countdown" || phase === "recording");
    $("fc-guided-apply").hidden = !(done && !done.applied);
    if (done) $("fc-guided-apply").textContent = done.problem ? "apply anyway" : "apply";
    $("fc-guided-undo").hidden = !(done && done.undo);
    $("fc-guided-save").hidden = $("fc-guided-path").hidden = !done;
  }

  // The prompt at `elapsed` s into the script (null between prompts), and the next one.
  function at(elapsed) {
    const now = script.prompts.find((p) => p.start <= elapsed && elapsed < p.start + p.duration) || null;
    const next = script.prompts.find((p) => p.start > elapsed) || null;
    return { now, next };
  }

  function show(text) {
    const el = $("fc-countdown");
    el.hidden = !text;
    el.textContent = text;
    $("fc-guided-now").textContent = text;
    if (text) api.guidedShown.push(text);
  }

  function progress(m) {
    if (m.phase === "countdown") {
      show(`guided calibration in ${m.remaining.toFixed(1)} s · first: ${script.prompts[0].text}`);
      return;
    }
    const { now, next } = at(m.elapsed);
    for (const p of script.prompts) {
      const r = rows.get(p.id);
      const state = p.start + p.duration <= m.elapsed ? "done" : p === now ? "now" : "";
      if (r.row.className !== state) r.row.className = state;
      r.state.textContent = state === "done" ? "done" : state === "now" ? "now" : "";
    }
    if (now) show(`${now.text} · ${(now.start + now.duration - m.elapsed).toFixed(1)} s`);
    else if (next) show(`rest · next: ${next.text} in ${(next.start - m.elapsed).toFixed(1)} s`);
    else show(`hold still · ${(script.seconds + script.tail - m.elapsed).toFixed(1)} s`);
    $("fc-guided-summary").textContent = `recording: ${m.frames} frames`;
  }

  function result(m) {
    for (const p of m.prompts) {
      const r = rows.get(p.id);
      r.row.className = p.seen ? "seen" : "missed";
      r.state.textContent = p.seen ? "seen" : p.why;
      r.peak.textContent = p.aim === null ? "" : `${f2(p.before)} → ${f2(p.after)} (${f2(p.aim)})`;
    }
    const what = m.applied ? "applied" : "not applied";
    $("fc-guided-summary").textContent =
      `${m.seen} of ${m.prompts.length} prompts seen in ${m.take} (${m.frames} frames, tracker ${m.tracker}); ${what}` +
      (m.problem ? `: ${m.problem}` : "");
    $("fc-guided-summary").classList.toggle("bad", !!m.problem);
    const changes = $("fc-guided-channels").tBodies[0] || $("fc-guided-channels").createTBody();
    changes.replaceChildren();
    for (const c of m.channels.slice(0, SHOWN_CHANNELS)) {
      const row = changes.insertRow();
      row.insertCell().textContent = c.name;
      let text = `gain ${c.gain.toFixed(2)}`;
      if (c.neutral !== undefined) text += `, neutral ${c.neutral.toFixed(3)}${c.lifted ? ", lifted to its aim" : ""}`;
      if (c.offset) text += `, offset ${c.offset >= 0 ? "+" : ""}${c.offset.toFixed(3)}`;
      for (const [name, v] of c.cross || []) text += `, ${v >= 0 ? "+" : "−"} ${Math.abs(v).toFixed(2)} × ${name}`;
      if (c.own) text += ", read as its own rise alone (the map's other inputs misread this face)";
      if (c.shut) text += `, lifted from ${c.shut[0].toFixed(2)} so that its closure ${c.shut[1].toFixed(2)} reads 1`;
      row.insertCell().textContent = text;
    }
  }

  return {
    on(m) {
      api.guidedPhase = m.phase;
      if (m.phase === "countdown" || m.phase === "recording") {
        buttons(m.phase);
        return progress(m);
      }
      show("");
      if (m.phase === "fitting") {
        $("fc-guided-summary").textContent = "fitting…";
        return buttons(m.phase);
      }
      if (m.phase === "stopped") {
        $("fc-guided-summary").textContent = `stopped: ${m.why}`;
        return buttons("idle");
      }
      if (m.phase === "done") {
        api.guided = m;
        result(m);
        buttons("done", m);
      }
    },
  };
}
