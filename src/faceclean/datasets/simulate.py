"""Tracker-artefact simulator: (noisy, truth) pairs from clean animation.

It models what consumer face trackers do to a performance: the clean take is sampled at
the tracker's own (possibly irregular) instants, then degraded by soft saturation,
crosstalk, slow drift, velocity-dependent jitter, occlusion spikes, clipping to [0, 1],
frozen frames, tracking-loss gaps and dropped frames, in that order. Every parameter is
drawn per sequence from a preset's documented ranges (``PRESETS``) and everything is
seeded: the same seed gives the same arrays.

    noisy, truth = corrupt(clean, seed=3, preset="iphone")

or, with explicit parameters::

    rng = np.random.default_rng(3)
    params = dataclasses.replace(sample_params(rng, "webcam"), fps=30.0)
    noisy, truth = apply(clean, params, rng)
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from scipy.signal import butter, lfilter

from faceclean.animation import MAX_MADE, Animation
from faceclean.channels import ARKIT52, INDEX
from faceclean.errors import FacecleanError, within
from faceclean.errors import seed as check_seed
from faceclean.timing import hold_last, resample, runs, stream_times

MAX_STRENGTH = 100.0  # artefact scale bound (corrupt --strength)


@dataclass(frozen=True)
class Params:
    """One sequence's artefacts. Ranges are the widest any preset uses; 0 disables."""

    fps: float = 60.0  # Hz, 24-120: the tracker's nominal rate
    timing_irregularity: float = 0.0  # 0-0.4: std of a frame interval over the period
    jitter: float = 0.0  # 0-0.03: base noise std, weight units
    jitter_velocity: float = 0.0  # s, 0-0.01: extra noise std per unit/s of channel speed
    jitter_cutoff: float = 1000.0  # Hz, 4-16: low-pass of the noise (trackers smooth it)
    jitter_white: float = 1.0  # 0-1: share of the noise variance left white (unfiltered)
    channel_spread: float = 0.0  # 0-0.6: log-std of the per-channel noise scale
    blink_peak: float = 1.0  # 0.55-1: what a full blink (1.0) reads as (1 = no saturation)
    peak: float = 1.0  # 0.75-1: other channels' full activation reads as U(peak, 1)
    crosstalk_lr: float = 0.0  # 0-0.15: share of a channel replaced by its other side
    crosstalk_jaw: float = 0.0  # 0-0.25: jawOpen added into mouthClose
    crosstalk_brow: float = 0.0  # 0-0.2: browInnerUp <-> browOuterUp leakage
    drift: float = 0.0  # 0-0.04: std of the slow per-channel bias
    drift_period: float = 20.0  # s, 5-40: shortest period of the bias wander
    spike_rate: float = 0.0  # 1/s, 0-0.5: occlusion glitches per second
    spike_amplitude: float = 0.3  # 0.1-0.6: peak size of a glitch
    spike_duration: float = 0.06  # s, 0.02-0.15: length of a glitch
    freeze_rate: float = 0.0  # 0-0.05: fraction of frames that repeat the last solve
    drop_rate: float = 0.0  # 0-0.1: fraction of frames never delivered
    drop_burst: float = 1.0  # frames, 1-6: mean length of a run of dropped frames
    loss_rate: float = 0.0  # 1/min, 0-3: tracking-loss gaps per minute
    loss_duration: float = 0.5  # s, 0.2-1.5: mean length of a tracking-loss gap
    # Drawn only by presets that name them ("wide"), so older presets keep their draws:
    knee: float = 4.0  # 1.5-8: sharpness n of the saturation x / (1 + (x/c)^n)^(1/n)
    crosstalk_eye: float = 0.0  # 0-0.25: eyeBlink leaks into eyeLookDown, eyeSquint
    crosstalk_mouth: float = 0.0  # 0-0.15: jawOpen -> funnel/lowerDown, smile -> cheekSquint


# field -> ((low, high) for "iphone", (low, high) for "webcam"): the two measured presets,
# side by side. Drawn uniformly (fps log-uniformly); fields left out keep the Params default.
_MEASURED = {
    "fps": ((60.0, 60.0), (24.0, 30.0)),
    "timing_irregularity": ((0.0, 0.02), (0.1, 0.35)),
    "jitter": ((0.01, 0.02), (0.012, 0.03)),
    "jitter_velocity": ((0.001, 0.005), (0.003, 0.01)),
    "jitter_cutoff": ((8.0, 16.0), (4.0, 10.0)),
    "jitter_white": ((0.03, 0.1), (0.05, 0.3)),
    "channel_spread": ((0.3, 0.5), (0.3, 0.6)),
    "blink_peak": ((0.65, 0.92), (0.55, 0.85)),
    "peak": ((0.85, 1.0), (0.75, 0.95)),
    "crosstalk_lr": ((0.0, 0.08), (0.03, 0.15)),
    "crosstalk_jaw": ((0.0, 0.15), (0.05, 0.25)),
    "crosstalk_brow": ((0.0, 0.1), (0.03, 0.2)),
    "drift": ((0.0, 0.02), (0.01, 0.04)),
    "drift_period": ((10.0, 40.0), (5.0, 20.0)),
    "spike_rate": ((0.0, 0.15), (0.1, 0.5)),
    "spike_amplitude": ((0.1, 0.4), (0.2, 0.6)),
    "spike_duration": ((0.02, 0.08), (0.05, 0.15)),
    "freeze_rate": ((0.0, 0.01), (0.01, 0.05)),
    "drop_rate": ((0.0, 0.04), (0.03, 0.1)),
    "drop_burst": ((1.0, 6.0), (1.0, 3.0)),
    "loss_rate": ((0.0, 0.5), (0.5, 3.0)),
    "loss_duration": ((0.2, 0.8), (0.3, 1.5)),
}  # fmt: skip
# preset -> field -> (low, high). "mixed" spans both measured presets and every rate: the
# training preset.
PRESETS: dict[str, dict[str, tuple[float, float]]] = {
    "clean": {"jitter": (0.0005, 0.001)},
    "iphone": {k: iphone for k, (iphone, _) in _MEASURED.items()},
    "webcam": {k: webcam for k, (_, webcam) in _MEASURED.items()},
}
PRESETS["mixed"] = {
    k: (min(PRESETS["iphone"][k][0], lo), max(PRESETS["iphone"][k][1], hi))
    for k, (lo, hi) in PRESETS["webcam"].items()
}
PRESETS["mixed"]["fps"] = (24.0, 120.0)
# "wide": the training preset of the adaptive cleaner (issue 11): "mixed" with noise from
# white to strongly low-passed, per-channel levels spread wider, under-shoot from none to
# severe on any channel with a knee of any sharpness, crosstalk between more related
# channels (eyeBlink -> eyeLookDown, eyeSquint; jawOpen -> mouth; smile -> cheekSquint).
# Its severity stays that of "mixed": a first, harsher draw (white noise to 100 %, gains
# per channel) made the learned filter worse than raw on held-out takes (docs/MODEL.md).
PRESETS["wide"] = {
    **PRESETS["mixed"],
    "jitter_cutoff": (3.0, 24.0),
    "jitter_white": (0.0, 0.6),
    "channel_spread": (0.0, 0.7),
    "blink_peak": (0.55, 1.0),
    "peak": (0.7, 1.0),
    "drift_period": (3.0, 40.0),
    "knee": (1.5, 8.0),
    "crosstalk_eye": (0.0, 0.25),
    "crosstalk_mouth": (0.0, 0.15),
}
_OPTIONAL = ("knee", "crosstalk_eye", "crosstalk_mouth")

# Fields that ``strength`` scales (a rate or a size); the saturation peaks move toward 1.
_SCALED = (
    "timing_irregularity", "jitter", "jitter_velocity", "crosstalk_lr", "crosstalk_jaw",
    "crosstalk_brow", "drift", "spike_rate", "spike_amplitude", "freeze_rate", "drop_rate",
    "loss_rate",
)  # fmt: skip
_CAPS = {"timing_irregularity": 0.8, "crosstalk_lr": 0.45, "freeze_rate": 0.5, "drop_rate": 0.5}


def sample_params(
    rng: np.random.Generator, preset: str = "iphone", strength: float = 1.0
) -> Params:
    """Draw one sequence's :class:`Params` from a preset's ranges, scaled by ``strength``
    (0 = nothing but the tracker's timing, 1 = the preset, 2 = twice the artefacts)."""
    if preset not in PRESETS:
        raise FacecleanError(f"unknown simulator preset {preset!r} (known: {', '.join(PRESETS)})")
    within(strength, "strength", 0.0, MAX_STRENGTH)  # 1e308 would overflow the draws
    values = {}
    for f in fields(Params):  # fixed field order: the draws do not depend on dict order
        if f.name in _OPTIONAL and f.name not in PRESETS[preset]:
            values[f.name] = f.default  # not drawn: older presets keep their streams
            continue
        lo, hi = PRESETS[preset].get(f.name, (f.default, f.default))
        if f.name == "fps":
            values[f.name] = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        else:
            values[f.name] = float(rng.uniform(lo, hi))
    for name in _SCALED + ("crosstalk_eye", "crosstalk_mouth"):
        values[name] = min(values[name] * strength, _CAPS.get(name, np.inf))
    for name in ("blink_peak", "peak"):
        values[name] = float(np.clip(1.0 - strength * (1.0 - values[name]), 0.3, 1.0))
    return Params(**values)


def corrupt(
    clean: Animation, seed: int, preset: str = "iphone", strength: float = 1.0
) -> tuple[Animation, Animation]:
    """(noisy, truth) for a clean take, both at the noisy stream's timestamps.

    The truth is the clean take linearly resampled there. Dropped frames are absent from
    both; tracking-loss gaps are all-NaN rows in ``noisy`` while ``truth`` keeps values;
    frames the source itself lacks are NaN in both. Same seed, same output.
    """
    rng = np.random.default_rng(check_seed(seed))
    return apply(clean, sample_params(rng, preset, strength), rng)


def apply(
    clean: Animation, params: Params, rng: np.random.Generator
) -> tuple[Animation, Animation]:
    """Degrade ``clean`` with explicit ``params``; per-channel draws come from ``rng``."""
    x, present = clean.arkit()
    times = clean.times
    ok = clean.valid & np.isfinite(times)
    back = np.any(np.diff(times[np.isfinite(times)]) < 0)
    if ok.sum() < 2 or back or times[ok][-1] <= times[ok][0]:  # all at one time: no span
        raise FacecleanError("simulator needs at least 2 valid frames with increasing times")
    if not 1.0 <= params.fps <= 1000.0:
        raise FacecleanError(f"simulator rate must be 1-1000 Hz, got {params.fps}")
    span = float(times[ok][-1] - times[ok][0])  # s: times a million times off asked 116 GiB
    if span * params.fps > MAX_MADE:
        n = span * params.fps
        raise FacecleanError(f"the take spans {span:.6g} s: {n:.3g} frames at {params.fps:g} "
                             f"Hz (at most {MAX_MADE:,}; are its times in s?)")  # fmt: skip
    t = stream_times(times[ok][0], times[ok][-1], params.fps, params.timing_irregularity, rng)
    if np.any(np.diff(t) <= 0.0):  # times near 1e15 s: a frame step below float64's step there
        raise FacecleanError(
            f"the take's times (from {times[ok][0]:.6g} s) are too large to step by "
            f"{1.0 / params.fps:.3g} s frames in float64; give it times from 0"
        )
    truth = resample(times[np.isfinite(times)], x[np.isfinite(times)], t)  # (N, 52)
    seen = ~np.isnan(truth).all(1)  # (N,) the source has this instant
    y = np.where(seen[:, None], truth, 0.0)
    blank = np.isnan(y)  # cells the source lacks (a channel never tracked): NaN again at the
    y = np.where(blank, 0.0, y)  # end, never mixed into the others by the crosstalk
    n = len(t)

    y = _saturate(y, params, rng)
    y = y @ _crosstalk(params, rng).T
    y += _drift(t, params, rng)
    y += _jitter(t, y, params, rng)
    y += _spikes(t, params, rng)
    y = np.clip(y, 0.0, 1.0)  # the tracker's channel range

    y = hold_last(y, runs(n, params.freeze_rate / 1.5, 1.5, rng))
    lost = runs(n, params.loss_rate / 60.0 / params.fps, params.loss_duration * params.fps, rng)
    y[lost | ~seen] = np.nan
    y[blank] = np.nan
    keep = ~runs(n, params.drop_rate / params.drop_burst, params.drop_burst, rng)
    if keep.sum() < 2:
        keep[:] = True
    names = tuple(ARKIT52[i] for i in np.flatnonzero(present))
    cols = present
    kept = {k: clean.meta[k] for k in ("format", "timecode_start") if k in clean.meta}
    noisy_pose, true_pose = _pose(clean, t, lost | ~seen, rng)  # drawn last: same blendshapes
    meta = {"simulator": _describe(params), **kept}
    if noisy_pose is not None:
        names_p = {"pose_names": tuple(clean.meta["pose_names"])}
        meta.update(pose=noisy_pose[keep], **names_p)
        kept = {**kept, "pose": true_pose[keep], **names_p}
    noisy = Animation(t[keep], y[keep][:, cols], names, meta)
    return noisy, Animation(t[keep], truth[keep][:, cols], names, kept)


# rad, per POSE angle: the raw Live Link stream's frame noise (llv_dao.npz, the angles minus
# a 9-frame quadratic Savitzky-Golay fit: benchmarks/tune_rotation.py raw_jitter()); with
# POSE_OUTLIERS of the frames off by POSE_OUTLIER_RAD, as the rotation filter is tuned on
POSE_JITTER = (0.00193, 0.00384, 0.00191, 0.00384, 0.00747, 0.00034, 0.00379, 0.00745, 0.00040)
POSE_OUTLIERS = 0.005
POSE_OUTLIER_RAD = float(np.radians(3.0))


def _pose(
    clean: Animation, t: np.ndarray, lost: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(noisy, true) head/eye angles (N, P) at the stream's times ``t``, or (None, None)
    when the take has none. The truth is resampled on the unwrapped circle (a turn
    through +-pi goes the short way); the noisy angles add POSE_JITTER and outliers, and
    are NaN where the blendshapes lost tracking. Other pose columns pass resampled."""
    from faceclean.channels import POSE
    from faceclean.filters.rotation import wrap

    pose, names = clean.meta.get("pose"), tuple(clean.meta.get("pose_names", ()))
    if pose is None or not names:
        return None, None
    p = np.asarray(pose, np.float64)
    if p.shape != (clean.n_frames, len(names)):
        return None, None
    ok = np.isfinite(clean.times)
    q = p[ok].copy()
    angle = np.array([n in POSE for n in names])
    for j in np.flatnonzero(angle):
        f = np.isfinite(q[:, j])
        q[f, j] = np.unwrap(q[f, j])
    truth = resample(clean.times[ok], q, t)
    sigma = np.array([POSE_JITTER[POSE.index(n)] if n in POSE else 0.0 for n in names])
    noisy = truth + rng.normal(0.0, 1.0, truth.shape) * sigma
    hit = rng.random(len(t)) < POSE_OUTLIERS
    noisy[np.ix_(hit, angle)] += (
        rng.choice([-1.0, 1.0], (hit.sum(), angle.sum())) * POSE_OUTLIER_RAD
    )
    noisy[lost] = np.nan
    truth[:, angle], noisy[:, angle] = wrap(truth[:, angle]), wrap(noisy[:, angle])
    return noisy, truth


def _describe(params: Params) -> dict[str, float]:
    return {f.name: getattr(params, f.name) for f in fields(Params)}


def _knee(peak: np.ndarray, k: float = 4.0) -> np.ndarray:
    """Ceiling c of x / (1 + (x/c)^k)^(1/k) such that x = 1 reads as ``peak`` (inf at 1)."""
    peak = np.clip(peak, 1e-3, 1.0)
    with np.errstate(divide="ignore"):
        return np.where(peak < 1.0, (peak**-k - 1.0) ** (-1.0 / k), np.inf)


def _saturate(y: np.ndarray, p: Params, rng: np.random.Generator) -> np.ndarray:
    """Soft saturation: large activations top out (blinks that never fully close)."""
    peak = rng.uniform(p.peak, 1.0, 52)
    blink = p.blink_peak + rng.uniform(-0.03, 0.03, 2) * (p.blink_peak < 1.0)
    peak[[INDEX["eyeBlinkLeft"], INDEX["eyeBlinkRight"]]] = blink
    k = p.knee
    c = _knee(peak, k)
    pos = np.maximum(y, 0.0)
    return np.where(y > 0.0, pos / (1.0 + (pos / c) ** k) ** (1.0 / k), y)


_LR_PAIRS = [
    (INDEX[n], INDEX[n[:-4] + "Right"])
    for n in ARKIT52
    if n.endswith("Left") and not n.startswith("eyeLook") and n not in ("jawLeft", "mouthLeft")
]


def _crosstalk(p: Params, rng: np.random.Generator) -> np.ndarray:
    """(52, 52) mixing matrix C, noisy = C @ clean per frame."""
    c = np.eye(52)
    share = p.crosstalk_lr * rng.uniform(0.5, 1.0, (len(_LR_PAIRS), 2))
    for (left, right), (a, b) in zip(_LR_PAIRS, share, strict=True):
        c[left, left], c[left, right] = 1.0 - a, a
        c[right, right], c[right, left] = 1.0 - b, b
    c[INDEX["mouthClose"], INDEX["jawOpen"]] += p.crosstalk_jaw
    inner, outer = INDEX["browInnerUp"], [INDEX["browOuterUpLeft"], INDEX["browOuterUpRight"]]
    c[inner, outer] += p.crosstalk_brow / 2.0
    c[outer, inner] += p.crosstalk_brow
    for side in ("Left", "Right"):  # the eyelid drags the gaze and the squint with it
        blink = INDEX["eyeBlink" + side]
        c[INDEX["eyeLookDown" + side], blink] += p.crosstalk_eye
        c[INDEX["eyeSquint" + side], blink] += 0.5 * p.crosstalk_eye
        c[INDEX["cheekSquint" + side], INDEX["mouthSmile" + side]] += p.crosstalk_mouth
    for target in ("mouthFunnel", "mouthLowerDownLeft", "mouthLowerDownRight"):
        c[INDEX[target], INDEX["jawOpen"]] += 0.5 * p.crosstalk_mouth
    return c


def _drift(t: np.ndarray, p: Params, rng: np.random.Generator) -> np.ndarray:
    """(N, 52) slow bias: per-channel sum of 3 sinusoids of period drift_period..4x, unit RMS."""
    if p.drift <= 0.0:
        return np.zeros((len(t), 52))
    coarse = np.arange(t[0], t[-1] + 0.5, 0.25)  # s; the bias is smooth, interpolate it
    period = rng.uniform(p.drift_period, 4.0 * p.drift_period, (1, 3, 52))
    phase = rng.uniform(0.0, 2.0 * np.pi, (1, 3, 52))
    wave = np.sin(2.0 * np.pi * coarse[:, None, None] / period + phase).sum(1) / np.sqrt(1.5)
    gain = p.drift * rng.standard_normal(52)
    return resample(coarse, wave * gain, t, max_gap=np.inf)


def _jitter(t: np.ndarray, y: np.ndarray, p: Params, rng: np.random.Generator) -> np.ndarray:
    """(N, 52) noise, std per channel scale * (jitter + jitter_velocity * |dy/dt|)."""
    speed = np.abs(np.gradient(y, t, axis=0)) if len(t) > 1 else np.zeros_like(y)  # 1/s
    scale = np.exp(p.channel_spread * rng.standard_normal(52))
    e = rng.standard_normal(y.shape)
    if p.jitter_white < 1.0 and p.jitter_cutoff < 0.45 * p.fps:
        b, a = butter(2, p.jitter_cutoff / (0.5 * p.fps))  # per nominal frame
        gain = np.sqrt(np.sum(lfilter(b, a, np.eye(1, 512)[0]) ** 2))  # unit variance
        smooth = lfilter(b, a, rng.standard_normal(y.shape), axis=0) / gain
        e = np.sqrt(p.jitter_white) * e + np.sqrt(1.0 - p.jitter_white) * smooth
    return e * scale * (p.jitter + p.jitter_velocity * speed)


# Channels a hand, hair or a bad frame can hit together.
_REGIONS = [
    [i for i, n in enumerate(ARKIT52) if n.startswith(prefix)]
    for prefix in (("eye",), ("brow",), ("mouth", "jaw", "tongue"), ("cheek", "nose", "mouth"))
]


def _spikes(t: np.ndarray, p: Params, rng: np.random.Generator) -> np.ndarray:
    """(N, 52) occlusion glitches: triangular bumps on 2-5 channels of one face region."""
    out = np.zeros((len(t), 52))
    count = rng.poisson(p.spike_rate * (t[-1] - t[0])) if p.spike_rate > 0 else 0
    for _ in range(count):
        center = rng.uniform(t[0], t[-1])
        half = 0.5 * p.spike_duration * rng.uniform(0.5, 1.5)
        region = _REGIONS[rng.integers(len(_REGIONS))]
        chans = rng.choice(region, size=rng.integers(2, 6), replace=False)
        sign = np.where(rng.random(len(chans)) < 0.7, 1.0, -1.0)
        amp = p.spike_amplitude * rng.uniform(0.5, 1.0, len(chans)) * sign
        lo, hi = np.searchsorted(t, [center - half, center + half])
        if hi <= lo:  # shorter than a frame: the nearest frame takes it whole
            lo = int(np.clip(np.searchsorted(t, center), 0, len(t) - 1))
            hi = lo + 1
        shape = np.maximum(1.0 - np.abs(t[lo:hi] - center) / half, 0.2)
        out[lo:hi, chans] += shape[:, None] * amp
    return out
