// A slider row for one key: its name, a 0..1000 range input mapped onto [lo, hi] (log or
// linear), and the value shown to 3 significant digits (what is sent is what is shown).
// Ranges of the known smoothing keys: [lo, hi, log scale?] in the key's units.
export const RANGES = {
  min_cutoff: [0.01, 50, true], beta: [0.001, 100, true], d_cutoff: [0.1, 30, true],
  tau: [0.001, 2, true], gamma: [0.01, 1, false], q: [0.01, 1000, true], r: [1e-4, 1, true],
  sigma: [0.001, 0.5, true], sigma_frames: [0.1, 50, true],
  detail: [0, 1, false], // the tracker map's: the share of its fitted detail (lag taken back)
  rest_drift: [0, 0.05, false], // the tracker map's: how fast its rest climbs back, weight/s
};
export const OTHER = [1e-3, 1e3, true]; // a smoothing key not in RANGES
// The levels' keys: [lo, hi, log scale?, the value when unset].
export const LEVELS = { gain: [0, 4, false, 1], offset: [-0.5, 0.5, false, 0], curve: [0.2, 5, true, 1] };

function toSlider(v, [lo, hi, log]) {
  const u = log ? Math.log(v / lo) / Math.log(hi / lo) : (v - lo) / (hi - lo);
  return Math.round(1000 * Math.min(Math.max(u, 0), 1));
}
function fromSlider(s, [lo, hi, log]) {
  const u = s / 1000;
  return log ? lo * (hi / lo) ** u : lo + u * (hi - lo);
}
function fmt(v) { return Math.abs(v) >= 100 ? v.toFixed(0) : +v.toPrecision(3) + ""; }

// The row, appended to holder; onValue(v) as the hand moves it. Its input is #fc-KEY.
export function slider(holder, key, value, range, onValue) {
  const row = document.createElement("div");
  row.className = "slider";
  const name = document.createElement("label");
  name.textContent = key;
  const input = document.createElement("input");
  input.type = "range"; input.min = "0"; input.max = "1000"; input.step = "1";
  input.id = `fc-${key}`;
  input.dataset.key = key;
  input.value = String(toSlider(value, range));
  const shown = document.createElement("span");
  shown.textContent = fmt(value);
  input.addEventListener("input", () => {
    const v = +fmt(fromSlider(+input.value, range));
    shown.textContent = fmt(v);
    onValue(v);
  });
  row.append(name, input, shown);
  holder.append(row);
}

// A new value only moves the slider (and its shown value), never the one in the hand.
export function moveSlider(key, value, range) {
  const input = document.getElementById(`fc-${key}`);
  if (!input || document.activeElement === input) return; // the one in the hand shows its own
  const at = String(toSlider(value, range));
  if (input.value !== at) input.value = at;
  const shown = input.nextElementSibling;
  if (shown.textContent !== fmt(value)) shown.textContent = fmt(value);
}
