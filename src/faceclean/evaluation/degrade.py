"""A second, independent tracker-artefact model, for evaluation only (never for training).

``degrade(clean, seed, condition, strength)`` turns clean animation into what a real-time
face tracker would have sent, so that a cleaner trained on another simulator is judged on
artefacts it has not seen. Every process lives in continuous time (seconds, Hz): a seed
draws one face-and-tracker "session" and the conditions only change how it is sampled.

Pipeline, with x(t) the clean take (linear interpolation between its rows), frame n
captured at t_c[n] and stamped at t_s[n]; ``s`` is ``strength`` (scales every amplitude
and every event rate; s = 0 gives noisy == truth clipped to [0, 1]):

1. Timing. "30/60/120 fps": t_c[n] = t0 + phi + n / (f (1 + k)), clock skew
   k ~ U[-2e-3, 5e-4], phase phi ~ U[0, 1/120) s. "webcam": the rate is a two-state
   telegraph process (f_hi ~ U[27, 30], f_lo ~ U[23, 26] Hz, dwell ~ Exp(U[2, 10] s)),
   capture instants solve Phi(t_c[n]) = n with Phi the integrated rate. Stamps:
   t_s = t_c + s (J - E[J]) + late, J ~ Gamma processing time (webcam only: mean
   U[5, 20] ms, CV U[0.3, 0.9]); "late" frames (Poisson, iPhone U[0.1, 1] Hz, webcam
   U[0.5, 2] Hz, x s) arrive U[0, D] later, D ~ U[2, 8] ms / U[10, 40] ms. Stamps are
   then forced to rise by at least 1 ms (a late frame pushes the next one). Content is
   taken at t_c, truth at t_s: the mismatch is the timing error a cleaner sees.
2. Crosstalk (leak matrix, delay per leak d ~ U[0, 40] ms), from the clean signal:
   additive leaks y_dst += s c x_src(t - d), e.g. eyeBlink -> eyeSquint U[0.05, 0.35],
   eyeBlink -> eyeWide U[-0.3, 0], eyeLookDown -> eyeBlink U[0.05, 0.3], jawOpen ->
   mouthClose/mouthFunnel/mouthLowerDown U[0, 0.15..0.2], mouthSmile -> cheekSquint
   U[0.05, 0.3], mouthPucker -> mouthFunnel U[0, 0.25] (see ``_LEAKS``); mirror leaks
   y_L += s c (x_R(t - d) - x_L(t)), c ~ U[0, 0.3], for every Left/Right pair and the
   conjugate gaze pairs (eyeLookInLeft ~ eyeLookOutRight, ...). Each leak is on with
   probability 0.7.
3. Response curve per channel (its own piecewise shape): u = (max(y - dz, 0) / (1 - dz))^g
   (dead zone dz, power g), out = u below the knee k, k + m (u - k) above it, with
   m = max((c - k) / (1 - k), 0.05) so that a full activation reads c. Eye blinks:
   dz U[0, .03], g U[.9, 1.1], k U[.4, .7], c U[.65, .95] (never fully closed);
   jawOpen: dz U[0, .02], g U[.9, 1.1], k U[.35, .6], c U[.8, 1] (compresses near the
   top); others: dz U[0, .025], g U[.9, 1.12], k U[.55, .9], c U[.85, 1]. Strength:
   dz s, g^s, c -> 1 - s (1 - c) (identity at s = 0).
4. Uncalibrated user: each channel with probability p ~ U[0.2, 0.6] gets out <- a out + b,
   log a ~ U[-0.15, 0.15], b ~ U[-0.02, 0.03] (a^s, b s).
5. Drift, added: per-channel Ornstein-Uhlenbeck wander (tau U[2, 15] s per session, x
   U[0.7, 1.4] per channel; std sigma_d U[0.004, 0.015] x lognormal(0, 0.4)), plus one
   shared factor (head pose; tau U[1, 8] s, std U[0.002, 0.01], loadings N(0, 1)), plus
   re-detection steps (Poisson U[0.02, 0.1] Hz and at every tracking-loss end):
   N(0, U[0.003, 0.015]) per channel, relaxing as exp(-(t - t_e) / U[1, 6] s).
   Webcam drift is x U[1.2, 2]. Generated on a 10 Hz grid, identical at every rate.
6. Noise, added: sigma_j m(x, v) (sqrt(w0) e + sqrt(w1) z1 + sqrt(w2) z2), e white,
   z1, z2 unit OU processes on the real stamps (tau1 U[8, 30] ms, tau2 U[60, 300] ms):
   the colour (w0, w1, w2) ~ Dirichlet(0.7, 0.7, 0.7) runs from white to brown.
   sigma_j = sigma U[0.002, 0.008] x lognormal(0, 0.35) x group (eyeBlink/eyeWide
   U[1.3, 2.5], other eye U[0.8, 1.5], brows U[0.8, 1.6]); webcam x U[1.5, 2.5].
   m(x, v) = (1 + a_mid 4 x (1 - x)) (1 + a_v min(|v| / 3 s^-1, 5)): noisier mid-range
   (a_mid U[0.5, 3]) and during fast motion (a_v U[0.2, 1.5]; v the clean slope).
7. Glitches: Poisson events, rate (Hz, x s) iPhone / webcam; a duration is U[lo, D] with
   the session's D drawn from the range given. Single-frame outliers U[0.05, 0.5] /
   U[0.2, 1] Hz on 1-5 channels (40 %: snap to U[0, 1]; else a +-U[0.1, 0.5] spike);
   bursts U[0.01, 0.08] / U[0.05, 0.25] Hz, U[0.06, 0.3] s on one face region (bias
   U[-0.15, 0.15] per channel + white noise of std U[0.03, 0.1]). Then values are
   clipped to [0, 1]. Frozen frames U[0.05, 0.3] / U[0.2, 0.8] Hz, U[0.02, D],
   D ~ U[0.02, 0.1] / U[0.04, 0.25] s: the tracker repeats its last output under new
   stamps. Tracking losses U[0.005, 0.03] / U[0.03, 0.12] Hz, U[0.1, D], D ~ U[0.1, 0.5] /
   U[0.1, 0.8] s: all-NaN rows. Drops U[0.05, 0.5] / U[1, 3] Hz, U[0, D], D ~ U[0, 30] /
   U[20, 100] ms: frames gone from both outputs. Each event touches at least the frame
   nearest its instant.

Random streams are keyed by (seed, purpose, channel): a channel's parameters do not depend
on which other channels the input has; session parameters, drift and event instants are
the same draw at 30/60/120 fps (webcam shares the parameters, with its own event family).
Measured at s = 1 on the 14 real takes (3 seeds each), MSE noisy vs truth: about 9e-4 at
30/60/120 fps and 1.7e-3 for webcam.
Source tracking loss (all-NaN rows in ``clean``): frames whose instants need a missing
source row are dropped from both outputs, so ``truth`` is never NaN there.
"""

from __future__ import annotations

import zlib

import numpy as np
from scipy.signal import lfilter

from faceclean.animation import Animation
from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52, INDEX, canonical, channel_key
from faceclean.errors import FacecleanError

CONDITIONS = ("30 fps", "60 fps", "120 fps", "webcam")
_RATE = {"30 fps": 30.0, "60 fps": 60.0, "120 fps": 120.0}

# (source, target, lo, hi): additive leak coefficient ranges; {S} is Left and Right.
_LEAKS = (
    ("eyeBlink{S}", "eyeLookDown{S}", 0.05, 0.3),
    ("eyeBlink{S}", "eyeSquint{S}", 0.05, 0.35),
    ("eyeBlink{S}", "eyeWide{S}", -0.3, 0.0),
    ("eyeBlink{S}", "cheekSquint{S}", 0.0, 0.1),
    ("eyeLookDown{S}", "eyeBlink{S}", 0.05, 0.3),
    ("jawOpen", "mouthClose", 0.0, 0.15),
    ("jawOpen", "mouthFunnel", 0.0, 0.15),
    ("jawOpen", "mouthLowerDown{S}", 0.0, 0.2),
    ("mouthSmile{S}", "cheekSquint{S}", 0.05, 0.3),
    ("mouthSmile{S}", "eyeSquint{S}", 0.0, 0.15),
    ("mouthPucker", "mouthFunnel", 0.0, 0.25),
    ("mouthFunnel", "mouthPucker", 0.0, 0.15),
    ("browInnerUp", "browOuterUp{S}", 0.0, 0.2),
    ("browDown{S}", "eyeSquint{S}", 0.0, 0.1),
    ("jawLeft", "mouthLeft", 0.0, 0.2),
    ("jawRight", "mouthRight", 0.0, 0.2),
)
_GAZE = (
    ("eyeLookInLeft", "eyeLookOutRight"),
    ("eyeLookOutLeft", "eyeLookInRight"),
    ("eyeLookUpLeft", "eyeLookUpRight"),
    ("eyeLookDownLeft", "eyeLookDownRight"),
)
_DIRECTIONS = {"jawLeft", "mouthLeft", "eyeLookInLeft", "eyeLookOutLeft"}
_MIRROR = (
    tuple(
        (n, n[:-4] + "Right")
        for n in ARKIT52
        if n.endswith("Left") and n not in _DIRECTIONS and not n.startswith("eyeLook")
    )
    + _GAZE
)


def _leak_table() -> list[tuple[str, str, float, float, bool]]:
    """Every possible leak: (source, target, lo, hi, mirror), in a fixed order."""
    table = []
    for src, dst, lo, hi in _LEAKS:
        sides = ("Left", "Right") if "{S}" in src + dst else ("",)
        table += [(src.format(S=s), dst.format(S=s), lo, hi, False) for s in sides]
    for a, b in _MIRROR:
        table += [(b, a, 0.0, 0.3, True), (a, b, 0.0, 0.3, True)]
    return table


_LEAK_TABLE = _leak_table()

# Response-curve ranges: dead zone, power, knee, value a full activation reaches.
_CURVE = {
    "blink": ((0, 0.03), (0.9, 1.1), (0.4, 0.7), (0.65, 0.95)),
    "jaw": ((0, 0.02), (0.9, 1.1), (0.35, 0.6), (0.8, 1.0)),
    "other": ((0, 0.025), (0.9, 1.12), (0.55, 0.9), (0.85, 1.0)),
}
_REGIONS = (("eye",), ("brow",), ("mouth", "jaw", "tongue"), ("cheek", "nose"))


def _rng(seed: int, *keys: int) -> np.random.Generator:
    """A random stream for one purpose: keys (purpose, channel, ...) are non-negative ints."""
    return np.random.default_rng([int(seed) % 2**64, *keys])


def _key(name: str) -> int:
    """A stable per-channel key: the ARKit index, else a hash of the spelling."""
    c = canonical(name)
    return INDEX[c] if c is not None else 1000 + zlib.crc32(name.encode())


def _session(seed: int) -> dict[str, float]:
    """Per-sequence scalars, one fixed draw order whatever the condition."""
    r = _rng(seed, 0)
    u = r.uniform
    p = {
        "skew": u(-2e-3, 5e-4), "phase": u(0, 1 / 120), "f_hi": u(27, 30), "f_lo": u(23, 26),
        "dwell": u(2, 10), "lat_mean": u(5e-3, 20e-3), "lat_cv": u(0.3, 0.9),
        "sigma": u(0.002, 0.008), "tau1": u(8e-3, 30e-3), "tau2": u(0.06, 0.3),
        "a_mid": u(0.5, 3), "a_v": u(0.2, 1.5), "webcam_noise": u(1.5, 2.5),
        "p_cal": u(0.2, 0.6), "drift_tau": u(2, 15), "drift_sd": u(0.004, 0.015),
        "head_tau": u(1, 8), "head_sd": u(0.002, 0.01), "step_sd": u(0.003, 0.015),
        "step_tau": u(1, 6), "redetect": u(0.02, 0.1), "webcam_drift": u(1.2, 2),
    }  # fmt: skip
    p["w0"], p["w1"], p["w2"] = r.dirichlet((0.7, 0.7, 0.7))
    # Event rates (Hz) and durations (s): index 0 iPhone, 1 webcam.
    for fam, ranges in enumerate(
        (
            dict(late=(0.1, 1), late_d=(2e-3, 8e-3), outlier=(0.05, 0.5), burst=(0.01, 0.08),
                 frozen=(0.05, 0.3), frozen_d=(0.02, 0.1), loss=(0.005, 0.03),
                 loss_d=(0.1, 0.5), drop=(0.05, 0.5), drop_d=(0.0, 0.03)),
            dict(late=(0.5, 2), late_d=(10e-3, 40e-3), outlier=(0.2, 1.0), burst=(0.05, 0.25),
                 frozen=(0.2, 0.8), frozen_d=(0.04, 0.25), loss=(0.03, 0.12),
                 loss_d=(0.1, 0.8), drop=(1, 3), drop_d=(0.02, 0.1)),
        )
    ):  # fmt: skip
        for k, (lo, hi) in ranges.items():
            p[f"{k}{fam}"] = u(lo, hi)
    return p


def _channel(seed: int, name: str) -> dict[str, float]:
    """Per-channel parameters (curve, gain/offset, noise and drift scales)."""
    c = canonical(name) or ""
    r = _rng(seed, 1, _key(name))
    role = "blink" if c.startswith("eyeBlink") else "jaw" if c == "jawOpen" else "other"
    dz, g, k, top = (r.uniform(lo, hi) for lo, hi in _CURVE[role])
    if c.startswith(("eyeBlink", "eyeWide")):
        group = r.uniform(1.3, 2.5)
    elif c.startswith("eye"):
        group = r.uniform(0.8, 1.5)
    elif c.startswith("brow"):
        group = r.uniform(0.8, 1.6)
    else:
        group = 1.0
    return {
        "dz": dz, "g": g, "k": k, "top": top, "u_cal": r.uniform(),
        "gain": np.exp(r.uniform(-0.15, 0.15)), "offset": r.uniform(-0.02, 0.03),
        "noise": group * r.lognormal(0, 0.35), "drift": r.lognormal(0, 0.4),
        "drift_tau": r.uniform(0.7, 1.4), "head": r.normal(),
    }  # fmt: skip


def _curve(y: np.ndarray, ch: dict[str, float], s: float) -> np.ndarray:
    """Step 3: the channel's response curve, blended to the identity by strength s."""
    dz, g, k = min(ch["dz"] * s, 0.9), ch["g"] ** s, ch["k"]
    top = float(np.clip(1 - s * (1 - ch["top"]), 0.0, 1.5))
    m = max((top - k) / (1 - k), 0.05)  # slope above the knee: h(1) = top
    u = (np.maximum(y - dz, 0.0) / (1 - dz)) ** g
    return np.where(u <= k, u, k + m * (u - k))


class _Source:
    """The clean take as a continuous signal: linear interpolation over its valid rows."""

    def __init__(self, clean: Animation) -> None:
        valid = clean.valid
        self.t, self.times, self.valid = clean.times[valid], clean.times, valid
        x = clean.values[valid]
        self.dead = ~np.isfinite(x).any(axis=0)  # (M,) channels with no value at all
        self.x = np.zeros_like(x)
        for j in np.flatnonzero(~self.dead):
            f = np.isfinite(x[:, j])
            self.x[:, j] = np.interp(self.t, self.t[f], x[f, j])
        self.t0, self.t1 = float(self.t[0]), float(self.t[-1])

    def at(self, t: np.ndarray, j: int | None = None) -> np.ndarray:
        """(N, M) values at instants t (or (N,) of channel j); clamped outside the take."""
        if j is not None:
            return np.interp(t, self.t, self.x[:, j])
        return np.stack([np.interp(t, self.t, col) for col in self.x.T], axis=1)

    def covered(self, t: np.ndarray) -> np.ndarray:
        """(N,) bool: instants inside the take whose bracketing source rows are both valid."""
        inside = (t >= self.t0) & (t <= self.t1)
        return inside & (np.interp(t, self.times, self.valid.astype(float)) > 1 - 1e-9)


def _poisson(r: np.random.Generator, rate: float, t0: float, t1: float) -> np.ndarray:
    """Sorted instants of a Poisson process of ``rate`` Hz on [t0, t1]."""
    return np.sort(r.uniform(t0, t1, r.poisson(max(rate, 0.0) * (t1 - t0))))


def _windows(t: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """(N,) bool: frames in any [start, start + length], and the frame nearest each start."""
    hit = np.zeros(len(t), bool)
    for a, d in zip(starts, lengths, strict=True):
        hit[np.searchsorted(t, a) : np.searchsorted(t, a + d, "right")] = True
        i = np.clip(np.searchsorted(t, a), 1, len(t) - 1)
        hit[i - 1 if a - t[i - 1] < t[i] - a else i] = True
    return hit


def _timing(seed, p, condition, t0, t1, s) -> tuple[np.ndarray, np.ndarray]:
    """Step 1: capture instants t_c and stamps t_s, (N,) seconds each."""
    fam = int(condition == "webcam")
    if fam:
        r = _rng(seed, 6)
        grid = np.arange(t0, t1 + 1e-3, 1e-3)  # 1 ms grid for the integrated rate
        switches = _poisson(r, 1 / p["dwell"], t0, t1)
        state = np.searchsorted(switches, grid) % 2  # telegraph: 0 high rate, 1 low
        phase = np.concatenate([[0.0], np.cumsum(np.where(state, p["f_lo"], p["f_hi"]))[:-1]])
        phase *= 1e-3
        t_c = np.interp(np.arange(0, phase[-1]), phase, grid)
        k = 1 / p["lat_cv"] ** 2  # Gamma shape from the coefficient of variation
        jitter = r.gamma(k, p["lat_mean"] / k, len(t_c)) - p["lat_mean"]
    else:
        f = _RATE[condition] * (1 + p["skew"])
        t_c = t0 + p["phase"] + np.arange(0, (t1 - t0 - p["phase"]) * f + 1) / f
        jitter = np.zeros(len(t_c))
    r = _rng(seed, 4, fam, 0)
    late = _poisson(r, p[f"late{fam}"] * s, t0, t1)
    delay = r.uniform(0, p[f"late_d{fam}"], len(late))
    t_s = t_c + s * jitter
    np.add.at(t_s, np.clip(np.searchsorted(t_c, late), 0, len(t_c) - 1), delay)
    n = np.arange(len(t_s)) * 1e-3  # stamps rise by >= 1 ms
    return t_c, np.maximum.accumulate(t_s - n) + n


def _drift(seed, p, names, chans, t, loss_ends, fam, s) -> np.ndarray:
    """Step 5: (N, M) OU wander + shared head factor + relaxing re-detection steps."""
    grid = np.arange(t[0] - 1, t[-1] + 1.1, 0.1)  # 10 Hz, same at every rate
    out = np.zeros((len(t), len(names)))

    def ou(r: np.random.Generator, tau: float, sd: float) -> np.ndarray:
        a = np.exp(-0.1 / tau)
        e = r.standard_normal(len(grid))
        z, _ = lfilter([np.sqrt(1 - a * a)], [1, -a], e[1:], zi=[a * e[0]])
        return sd * np.interp(t, grid, np.concatenate([[e[0]], z]))

    head = ou(_rng(seed, 3, 0), p["head_tau"], p["head_sd"])
    r = _rng(seed, 4, fam, 9)
    steps = np.concatenate([_poisson(r, p["redetect"] * s, t[0], t[-1]), loss_ends])
    amps = r.normal(0, p["step_sd"], (len(steps), len(names)))
    for j, (name, ch) in enumerate(zip(names, chans, strict=True)):
        wander = ou(_rng(seed, 3, 1 + _key(name)), p["drift_tau"] * ch["drift_tau"], 1.0)
        out[:, j] = p["drift_sd"] * ch["drift"] * wander + ch["head"] * head
    for te, amp in zip(steps, amps, strict=True):
        a, b = np.searchsorted(t, te), np.searchsorted(t, te + 6 * p["step_tau"])
        out[a:b] += amp * np.exp(-(t[a:b] - te) / p["step_tau"])[:, None]
    return s * out * (p["webcam_drift"] if fam else 1.0)


def _ou_stream(t: np.ndarray, tau: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Unit-variance OU processes sampled exactly at instants t: e (N, K, M) -> (N, K, M)."""
    a = np.exp(-np.diff(t)[:, None, None] / tau[None, :, None])  # (N-1, K, 1)
    b = np.sqrt(1 - a * a)
    z = np.empty_like(e)
    z[0] = e[0]
    for n in range(1, len(t)):
        z[n] = a[n - 1] * z[n - 1] + b[n - 1] * e[n]
    return z


def _check(clean: Animation, condition: str, strength: float) -> None:
    if condition not in CONDITIONS:
        raise FacecleanError(f"unknown condition {condition!r}: use one of {', '.join(CONDITIONS)}")
    if not np.isfinite(strength) or strength < 0:
        raise FacecleanError(f"strength must be a finite number >= 0, not {strength}")
    t = clean.times
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
        raise FacecleanError("degrade needs finite, non-decreasing timestamps in the take")
    tv = t[clean.valid]
    if clean.n_channels == 0 or len(tv) < 2 or tv[-1] <= tv[0]:
        raise FacecleanError("degrade needs a take with channels and at least 2 valid frames")


def degrade(
    clean: Animation, seed: int, condition: str = "60 fps", strength: float = 1.0
) -> tuple[Animation, Animation]:
    """(noisy, truth): both on the noisy stream's timestamps (seconds, increasing); truth is
    the clean take resampled (linear interpolation) at those instants. Dropped frames are
    absent from both. Tracking-loss frames are all-NaN rows in noisy, truth present there.
    Channels: same names and order as `clean`. Values of noisy in [0, 1] (a tracker's range).

    Frames that would need a missing (all-NaN) row of ``clean`` are dropped from both.
    ``condition`` is one of CONDITIONS; ``strength`` >= 0 scales every artefact (0: none).
    """
    _check(clean, condition, strength)
    s, names, src = float(strength), clean.names, _Source(clean)
    p, fam = _session(seed), int(condition == "webcam")
    t_c, t_s = _timing(seed, p, condition, src.t0, src.t1, s)
    n, m = len(t_c), len(names)
    x = src.at(t_c)  # (N, M) what the face did at capture
    chans = [_channel(seed, name) for name in names]
    cols = {
        channel_key(nm): int(j) for nm, j in zip(names, ChannelMap(names, names).src, strict=True)
    }

    # Step 2: crosstalk from the clean signal, each leak with its own delay.
    y = x.copy()
    r = _rng(seed, 2)
    for a, b, lo, hi, mirror in _LEAK_TABLE:
        c, d, on = r.uniform(lo, hi), r.uniform(0, 0.04), r.uniform() < 0.7
        if on and a in cols and b in cols:
            leak = src.at(t_c - d, cols[a]) - (x[:, cols[b]] if mirror else 0.0)
            y[:, cols[b]] += s * c * leak

    # Steps 3-4: response curve, then the uncalibrated gain and offset.
    for j, ch in enumerate(chans):
        y[:, j] = _curve(y[:, j], ch, s)
        if ch["u_cal"] < p["p_cal"]:
            y[:, j] = ch["gain"] ** s * y[:, j] + s * ch["offset"]

    # Events, same instants at every rate of one family.
    ev = [_rng(seed, 4, fam, k) for k in range(1, 6)]
    loss_t = _poisson(ev[3], p[f"loss{fam}"] * s, src.t0, src.t1)
    loss_d = ev[3].uniform(0.1, p[f"loss_d{fam}"], len(loss_t))

    # Steps 5-6: drift, then coloured, value- and speed-dependent noise.
    y += _drift(seed, p, names, chans, t_c, loss_t + loss_d, fam, s)
    fr = _rng(seed, 5, CONDITIONS.index(condition))
    e = fr.standard_normal((n, 3, m))
    z = _ou_stream(t_s, np.array([p["tau1"], p["tau2"]]), e[:, 1:])
    colour = np.sqrt(p["w0"]) * e[:, 0] + np.sqrt(p["w1"]) * z[:, 0] + np.sqrt(p["w2"]) * z[:, 1]
    h = 1 / 60  # s, central-difference half step for the clean slope
    v = (src.at(t_c + h) - src.at(t_c - h)) / (2 * h)  # (N, M) 1/s
    level = (1 + p["a_mid"] * 4 * np.clip(x, 0, 1) * (1 - np.clip(x, 0, 1))) * (
        1 + p["a_v"] * np.minimum(np.abs(v) / 3.0, 5.0)
    )
    sigma = s * p["sigma"] * np.array([ch["noise"] for ch in chans])
    y += sigma * (p["webcam_noise"] if fam else 1.0) * level * colour

    # Step 7: outliers and bursts, clip, frozen frames, tracking loss, drops.
    out_t = _poisson(ev[0], p[f"outlier{fam}"] * s, src.t0, src.t1)
    for te in out_t:
        i = min(np.searchsorted(t_c, te), n - 1)
        js = ev[0].choice(m, min(m, ev[0].integers(1, 6)), replace=False)
        snap, amp = ev[0].uniform(size=len(js)) < 0.4, ev[0].uniform(0.1, 0.5, len(js))
        sign = np.where(ev[0].uniform(size=len(js)) < 0.5, -1.0, 1.0)
        y[i, js] = np.where(snap, ev[0].uniform(size=len(js)), y[i, js] + sign * amp)
    for te in _poisson(ev[1], p[f"burst{fam}"] * s, src.t0, src.t1):
        dur, region = ev[1].uniform(0.06, 0.3), _REGIONS[ev[1].integers(len(_REGIONS))]
        bias, sd = ev[1].uniform(-0.15, 0.15, m), ev[1].uniform(0.03, 0.1)
        rows = _windows(t_c, np.array([te]), np.array([dur]))
        js = [j for j, nm in enumerate(names) if (canonical(nm) or "").startswith(region)]
        y[np.ix_(rows, js)] += bias[js] + sd * fr.standard_normal((rows.sum(), len(js)))
    y = np.clip(y, 0.0, 1.0)
    fz_t = _poisson(ev[2], p[f"frozen{fam}"] * s, src.t0, src.t1)
    frozen = _windows(t_c, fz_t, ev[2].uniform(0.02, p[f"frozen_d{fam}"], len(fz_t)))
    frozen[0] = False
    y = y[np.maximum.accumulate(np.where(frozen, 0, np.arange(n)))]  # repeat last output
    y[_windows(t_c, loss_t, loss_d)] = np.nan
    drop_t = _poisson(ev[4], p[f"drop{fam}"] * s, src.t0, src.t1)
    dropped = _windows(t_c, drop_t, ev[4].uniform(0, p[f"drop_d{fam}"], len(drop_t)))
    keep = ~dropped & src.covered(t_c) & src.covered(t_s)

    truth = src.at(t_s[keep])
    noisy = y[keep]
    noisy[:, src.dead] = truth[:, src.dead] = np.nan
    meta = {"degrade": {"seed": int(seed), "condition": condition, "strength": s}}
    return (
        Animation(t_s[keep], noisy, names, dict(meta)),
        Animation(t_s[keep].copy(), truth, names, dict(meta)),
    )
