"""One clip's versions side by side: input, truth, and the outputs of several cleaners.

What ``faceclean plot`` and ``faceclean report`` show. Everything is on the input's
timestamps: a truth recorded at other instants is interpolated onto them. Measures that
need no truth (jitter energy, spikes, gaps) live here too; those that need one are in
:mod:`faceclean.evaluation.metrics`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from faceclean.adjust import Adjust
from faceclean.animation import Animation
from faceclean.channel_map import ChannelMap
from faceclean.channels import channel_key
from faceclean.errors import FacecleanError
from faceclean.filters.rotation import clean_pose
from faceclean.resolve import DEFAULT, Choice, resolve
from faceclean.timing import refuse_restarts

SPIKE = 0.15  # weight units: a frame this far from its neighbours' median is a spike
SPIKE_HALF_WIDTH = 2  # frames each side in that median


@dataclass(eq=False)
class Comparison:
    """Input, truth (or None) and cleaned versions, all at the input's timestamps.

    ``outputs`` maps a label (the method spec) to its output; the first is the main
    cleaner's, the one the report's face shows next to the input.
    """

    input: Animation
    truth: Animation | None
    outputs: dict[str, Animation] = field(default_factory=dict)
    levels: list[str] = field(default_factory=list)  # the level mapping before the cleaners

    @property
    def main(self) -> str:
        return next(iter(self.outputs))

    @property
    def times(self) -> np.ndarray:
        """(N,) seconds from the clip's first frame."""
        return self.input.times - self.input.times[0]


def clean_with(spec: str | Choice, anim: Animation, adjust: Adjust | None = None,
               correct: bool = True) -> Animation:  # fmt: skip
    """The output on ``anim`` of the cleaner ``spec`` names (faceclean.resolve: words, and
    settings inline as ``WORDS:KEY=VALUE,KEY=VALUE``), after the level mapping ``adjust``
    with the spec's own level settings on top, as ``clean --calibration`` gives it: the
    calibration's rest reading handed to the cleaner and, if ``correct``, its correction
    after it (faceclean.adaptation); its head/eye angles (``meta["pose"]``) by the rotation
    filter."""
    from faceclean.adaptation import clean_calibrated

    choice = resolve(spec) if isinstance(spec, str) else spec
    adjust = (adjust or Adjust()).merged(choice.adjust(anim.names)) if choice.levels else adjust
    out = clean_calibrated(choice.build(anim.names), anim, adjust or Adjust(), correct=correct)
    return clean_pose(out, choice.build_pose)


def _corrects(adjust: Adjust | None, spec: str | Choice) -> bool:
    """Whether ``adjust``'s correction belongs after the cleaner ``spec`` names (one
    fitted after another cleaner is left off that one: ``clean`` refuses the pair)."""
    from faceclean.adaptation import check_cleaner

    words = spec if isinstance(spec, str) else spec.source
    try:
        check_cleaner(adjust.adaptation if adjust is not None else None, words, "")
    except FacecleanError:
        return False
    return True


def at_times(anim: Animation, times: np.ndarray, names: tuple[str, ...]) -> Animation:
    """``anim`` linearly interpolated at ``times`` (N,) s, columns in the order of
    ``names`` (matched by canonical name); NaN outside its time span or where absent."""
    times = np.asarray(times, dtype=np.float64)
    src = ChannelMap(names, anim.names).src
    out = np.full((len(times), len(names)), np.nan)
    if not (src >= 0).any():
        raise FacecleanError("the truth shares no channel with the input")
    found = False
    for i, j in enumerate(src):
        if j < 0:
            continue
        t, v = anim.times, anim.values[:, j]
        ok = np.isfinite(t) & np.isfinite(v)
        if ok.sum() < 2:
            continue
        found = True
        t, v = t[ok], v[ok]
        order = np.argsort(t, kind="stable")
        t, v = t[order], v[order]
        inside = (times >= t[0]) & (times <= t[-1])
        out[inside, i] = np.interp(times[inside], t, v)
    if not found:
        raise FacecleanError("the truth has fewer than 2 frames with values in the channels "
                             "it shares with the input")  # fmt: skip
    return Animation(times.copy(), out, tuple(names), {"format": "truth"})


def compare(
    noisy: Animation,
    truth: Animation | None = None,
    methods: Sequence[str | tuple[str, Choice]] = (),
    adjust: Adjust | None = None,
) -> Comparison:
    """Clean ``noisy`` with each method (the first is the main one; default: the shipped
    default cleaner): a spec string (its own label) or (label, resolved Choice); bring
    ``truth`` onto the input's timestamps. With an ``adjust`` the cleaners see its level
    mapping of ``noisy``; the input shown stays ``noisy``."""
    if noisy.n_frames < 2 or not noisy.valid.any():
        raise FacecleanError("the input has fewer than 2 frames with values")
    refuse_restarts(noisy, "the input")  # a cleaner would hold it still
    specs = dict(m if isinstance(m, tuple) else (m, m) for m in methods) or {DEFAULT: DEFAULT}
    if truth is not None:
        same = truth.n_frames == noisy.n_frames and np.array_equal(truth.times, noisy.times)
        names_match = [channel_key(n) for n in truth.names] == [channel_key(n) for n in noisy.names]
        if not (same and names_match):
            truth = at_times(truth, noisy.times, noisy.names)
        if not np.isfinite(truth.values).any():  # nothing to score against
            span = f"{noisy.times[0]:.6g}-{noisy.times[-1]:.6g} s"
            raise FacecleanError(f"the truth has no value within the input's times ({span})")
    outputs = {label: clean_with(s, noisy, adjust, k == 0 or _corrects(adjust, s))
               for k, (label, s) in enumerate(specs.items())}  # fmt: skip
    if adjust is None or adjust.is_identity:
        return Comparison(noisy, truth, outputs)
    return Comparison(noisy, truth, outputs, adjust.describe(noisy.names))


def jitter_energy(times: np.ndarray, values: np.ndarray) -> float:
    """Mean squared second time-derivative ((weight/s^2)^2) over channels and frames.

    Three-point formula on the real (possibly irregular) times; missing frames skipped.
    """
    ok = np.isfinite(times) & ~np.all(np.isnan(values), axis=1)
    t, x = times[ok], values[ok]
    keep = np.concatenate([[True], np.diff(t) > 0])
    t, x = t[keep], x[keep]
    if len(t) < 3:
        return float("nan")
    h = np.diff(t)[:, None]  # (N-1, 1) s
    d2 = 2.0 * np.diff(np.diff(x, axis=0) / h, axis=0) / (h[1:] + h[:-1])
    d2 = d2[np.isfinite(d2)]
    return float(np.mean(d2**2)) if d2.size else float("nan")


def _local_median(x: np.ndarray, k: int) -> np.ndarray:
    """(N, M) median of each frame's +-k neighbours, itself excluded (edges padded)."""
    pad = np.pad(x, ((k, k), (0, 0)), mode="edge")
    n = len(x)
    around = [pad[i : i + n] for i in range(2 * k + 1) if i != k]
    return np.nanmedian(np.stack(around), axis=0)


def spikes(input_values: np.ndarray, output_values: np.ndarray) -> tuple[int, int]:
    """(spikes in the input, spikes the output removed) over valid frames.

    A spike: a value more than SPIKE from the median of its +-2 neighbours. Removed: the
    output there is within half that distance of the same median.
    """
    rows = ~np.all(np.isnan(input_values), axis=1)
    x, y = input_values[rows], output_values[rows]
    if len(x) < 2 * SPIKE_HALF_WIDTH + 1:
        return 0, 0
    med = _local_median(x, SPIKE_HALF_WIDTH)
    dev = np.abs(x - med)
    found = dev > SPIKE
    removed = found & (np.abs(y - med) < 0.5 * dev)
    return int(found.sum()), int(removed.sum())


def gaps(input_values: np.ndarray, output_values: np.ndarray) -> tuple[int, int]:
    """(missing values in the input, of which the output filled) over all frames."""
    missing = np.isnan(input_values)
    return int(missing.sum()), int((missing & np.isfinite(output_values)).sum())


def change(input_values: np.ndarray, output_values: np.ndarray) -> np.ndarray:
    """(M,) RMS of output - input per channel (NaN-safe): how much cleaning changed it."""
    d = output_values - input_values
    ok = np.isfinite(d)
    sq = np.where(ok, d, 0.0) ** 2
    count = ok.sum(0)
    return np.sqrt(sq.sum(0) / np.maximum(count, 1))


def untruthed(comp: Comparison) -> dict[str, dict[str, float]]:
    """Measures without a truth, per output: jitter energy before/after, spikes, gaps."""
    t, x = comp.input.times, comp.input.values
    before = jitter_energy(t, x)
    rows = {}
    for label, out in comp.outputs.items():
        after = jitter_energy(t, out.values)
        found, removed = spikes(x, out.values)
        missing, filled = gaps(x, out.values)
        rows[label] = {
            "jitter_before": before,
            "jitter_after": after,
            "jitter_ratio": after / before if before > 0 else float("nan"),
            "spikes": found,
            "spikes_removed": removed,
            "missing": missing,
            "filled": filled,
        }
    return rows
