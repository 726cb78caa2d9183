"""Synthetic performer: plausible ARKit-52 performances to add variety to real takes.

A take is the sum of layers, each made of events with smooth envelopes:
a resting face with a slow idle wander; blinks with human timing (8-30 a minute,
a fast close of 70-100 ms, a slower open of 150-250 ms, both eyes together with a slight
asymmetry); gaze fixations joined by saccades; speech in phrases with pauses (syllables at
3-6 Hz driving the jaw and the lips through a few mouth shapes); and expressions (smile,
frown, brow raise, squint, ...) with smooth onsets. Every left/right pair moves together
with a small per-event asymmetry. Values in [0, 1]. Seeded: same seed, same take.
"""

from __future__ import annotations

import numpy as np

from faceclean.animation import MAX_MADE, Animation
from faceclean.channels import INDEX
from faceclean.errors import FacecleanError
from faceclean.errors import seed as check_seed


def sines(t: np.ndarray, seed: int = 0) -> np.ndarray:
    """(N, 52) smooth ARKit-52 weights in [0.2, 0.8] at times t (N,) s: per channel two slow
    sines (0.3-1.1 Hz, seeded phases). The cleaner contract's curve (tests/test_contract.py)
    and the map fit's rate check (neural/map_rises.py ``keeps_rate``) draw the same one."""
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * np.pi, (2, len(INDEX)))
    freq = rng.uniform(0.3, 1.1, (2, len(INDEX)))  # Hz
    tt = np.asarray(t, np.float64)[:, None]
    return (
        0.5
        + 0.15 * np.sin(2 * np.pi * freq[0] * tt + phase[0])
        + 0.15 * np.sin(2 * np.pi * freq[1] * tt + phase[1])
    )


def perform(seconds: float, seed: int, fps: float = 60.0, full_range: bool = False,
            net: bool = False) -> Animation:  # fmt: skip
    """A synthetic ARKit-52 performance of ``seconds`` s sampled at ``fps`` Hz.

    ``full_range``: add a range-of-motion layer (:func:`_range_of_motion`) that moves
    every channel, the rare ones too (tongueOut, jawLeft/Right, cheekPuff, noseSneer...),
    through its whole range. ``net``: opposite directions never held at once (``netted``)."""
    if not (np.isfinite(seconds) and 0.0 < seconds <= 24 * 3600.0):
        raise FacecleanError(f"seconds must be in (0, 86400], got {seconds}")
    if not (np.isfinite(fps) and 1.0 <= fps <= 1000.0):
        raise FacecleanError(f"fps must be in [1, 1000], got {fps}")
    if seconds * fps > MAX_MADE:  # a day at 1000 Hz asked 33 GB
        raise FacecleanError(f"{seconds:g} s at {fps:g} Hz is {seconds * fps:.3g} frames "
                             f"(at most {MAX_MADE:,}): fewer seconds, or a lower rate")  # fmt: skip
    rng = np.random.default_rng(check_seed(seed))
    t = np.arange(max(int(round(seconds * fps)), 1) + 1) / fps  # (N,) s, 0..seconds
    x = np.zeros((len(t), 52))
    x += _resting(rng) + _idle(t, rng)
    _speech(x, t, rng)
    _expressions(x, t, rng)
    _gaze(x, t, rng)
    _blinks(x, t, rng)
    if full_range:  # drawn after every other layer: plain takes keep their draws
        _range_of_motion(x, t, rng)
    x = np.clip(x, 0.0, 1.0)
    return Animation.from_arkit(t, netted(x) if net else x)


def independent(seconds: float, seed: int, fps: float = 60.0, net: bool = False) -> Animation:
    """A performer with no habits: every channel moves on its own over its whole range (the
    range-of-motion layer alone, events twice as dense), so that no source's co-activation
    (a smile that always comes with a squint) is learned as truth. Values in [0, 1].
    ``net``: opposite directions never held at once (``netted``)."""
    if not (np.isfinite(seconds) and 0.0 < seconds <= 24 * 3600.0):
        raise FacecleanError(f"seconds must be in (0, 86400], got {seconds}")
    rng = np.random.default_rng(check_seed(seed))
    t = np.arange(max(int(round(seconds * fps)), 1) + 1) / fps
    x = np.zeros((len(t), 52))
    _range_of_motion(x, t, rng, density=2.0)
    x = np.clip(x, 0.0, 1.0)
    return Animation.from_arkit(t, netted(x) if net else x)


# Channels that move one part in opposite directions: an eye cannot look in and out at
# once, nor a jaw or a mouth go left and right. Drawn on their own, both are held at once
# (a made-up performer held jawLeft and jawRight near 0.4 each), and a face shows their
# difference: the rendered eyeball turns by eyeLookOut - eyeLookIn exactly, ICT's jawLeft +
# jawRight deltas are a quarter of either's. A truth no image shows is nothing a tracker
# can be judged on, nor a map fitted to.
OPPOSITES = tuple(
    (f"{a}{side}", f"{b}{side}")
    for a, b in (("eyeLookIn", "eyeLookOut"), ("eyeLookUp", "eyeLookDown"))
    for side in ("Left", "Right")
) + (("jawLeft", "jawRight"), ("mouthLeft", "mouthRight"))


def netted(x: np.ndarray) -> np.ndarray:
    """(N, 52) weights with each pair of OPPOSITES replaced by their difference, on the
    side it falls: (a, b) -> (max(a - b, 0), max(b - a, 0))."""
    x = x.copy()
    for a, b in OPPOSITES:
        d = x[:, INDEX[a]] - x[:, INDEX[b]]
        x[:, INDEX[a]], x[:, INDEX[b]] = np.maximum(d, 0.0), np.maximum(-d, 0.0)
    return x


def _range_of_motion(x: np.ndarray, t: np.ndarray, rng: np.random.Generator,
                     density: float = 1.0) -> None:  # fmt: skip
    """Every channel, one event every 2-8 s on average: a smooth rise over 40 ms-1 s to
    a peak anywhere in 0.2-1 (a third of the events the channel's full 1), held 0-1.5 s,
    released as slowly or fast; left/right pairs move together a third of the time."""
    for j in range(52):
        for s in _events(t[-1], rng.uniform(2.0, 8.0) / density, rng):
            peak = 1.0 if rng.random() < 1 / 3 else rng.uniform(0.2, 1.0)
            attack, hold, release = (
                rng.uniform(0.04, 1.0),
                rng.uniform(0.0, 1.5),
                rng.uniform(0.04, 1.0),
            )
            w = np.zeros(52)
            w[j] = peak
            if rng.random() < 1 / 3 and _MIRROR[j] != j:
                w[_MIRROR[j]] = peak * rng.uniform(0.8, 1.0)
            _add(x, t, s, attack, hold, release, w)


_MIRROR = np.array([
    INDEX.get(n[:-4] + "Right", i) if n.endswith("Left") else
    INDEX.get(n[:-5] + "Left", i) if n.endswith("Right") else i
    for i, n in enumerate(INDEX)
])  # fmt: skip


def _vec(spec: dict[str, float], left: float = 1.0, right: float = 1.0) -> np.ndarray:
    """(52,) weights from {"mouthSmile": 1.0, "jawOpen": 0.5}; a name without a side
    stands for its Left and Right channels, scaled by ``left`` and ``right``."""
    w = np.zeros(52)
    for name, value in spec.items():
        if name in INDEX:
            w[INDEX[name]] += value
        else:
            w[INDEX[name + "Left"]] += value * left
            w[INDEX[name + "Right"]] += value * right
    return w


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _add(
    x: np.ndarray,
    t: np.ndarray,
    start: float,
    attack: float,
    hold: float,
    release: float,
    weights: np.ndarray,
) -> None:
    """x += envelope(t) * weights: smooth rise over ``attack`` s, flat ``hold`` s, smooth
    fall over ``release`` s, from ``start`` s."""
    lo, hi = np.searchsorted(t, [start, start + attack + hold + release])
    if hi <= lo:
        return
    u = t[lo:hi] - start
    env = _smoothstep(u / attack) * (1.0 - _smoothstep((u - attack - hold) / release))
    x[lo:hi] += env[:, None] * weights


def _events(duration: float, mean_gap: float, rng: np.random.Generator, shape: float = 2.0):
    """Start times of events in [0, duration): gamma-distributed gaps with mean ``mean_gap``."""
    count = int(duration / mean_gap * 2) + 4
    gaps = rng.gamma(shape, mean_gap / shape, count)
    starts = np.cumsum(gaps) - gaps[0] * rng.random()
    while starts[-1] < duration:  # rare: draw more
        more = np.cumsum(rng.gamma(shape, mean_gap / shape, count))
        starts = np.concatenate([starts, starts[-1] + more])
    return starts[(starts >= 0) & (starts < duration)]


# Neutral face: ARKit rarely reads exactly 0 on these (levels from the real takes' medians).
_REST = _vec(
    {"eyeSquint": 0.12, "browInnerUp": 0.1, "mouthStretch": 0.1, "mouthFunnel": 0.06,
     "mouthShrugLower": 0.05, "mouthShrugUpper": 0.06, "mouthRollLower": 0.05,
     "jawForward": 0.04, "noseSneer": 0.04, "mouthLowerDown": 0.04, "jawOpen": 0.03,
     "eyeWide": 0.03, "cheekSquint": 0.03, "mouthClose": 0.02, "mouthFrown": 0.03}
)  # fmt: skip


def _resting(rng: np.random.Generator) -> np.ndarray:
    pair = 1.0 + 0.1 * rng.uniform(-1.0, 1.0, 52)
    return _REST * rng.uniform(0.3, 1.6, 52).reshape(1, 52) * pair


def _idle(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 52) slow wander of every channel (breathing, posture): 2 sines, 1-15 s periods."""
    amp = rng.uniform(0.005, 0.04, 52)
    period = rng.uniform(1.0, 15.0, (2, 52))
    phase = rng.uniform(0.0, 2.0 * np.pi, (2, 52))
    wave = np.sin(2.0 * np.pi * t[:, None, None] / period + phase).sum(1)
    idle = amp * (1.0 + 0.5 * wave)
    idle[:, INDEX["tongueOut"]] = 0.0
    return idle


def _blinks(x: np.ndarray, t: np.ndarray, rng: np.random.Generator) -> None:
    """Blinks: 10-25 a minute, gaps of 0.6 s or more; close 70-100 ms, closed 10-40 ms,
    open 150-250 ms; the right eye a few ms off and a few percent shallower or deeper."""
    rate = rng.uniform(10.0, 25.0)  # per minute
    starts = _events(t[-1], 60.0 / rate, rng, shape=3.0)
    starts = starts[np.diff(starts, prepend=-np.inf) > 0.6]
    left, right = INDEX["eyeBlinkLeft"], INDEX["eyeBlinkRight"]
    for s in starts:
        close, hold, opening = (
            rng.uniform(0.07, 0.1),
            rng.uniform(0.01, 0.04),
            rng.uniform(0.15, 0.25),
        )
        peak = rng.uniform(0.8, 1.0)
        offset = rng.uniform(-0.006, 0.006)  # s, right eye lead or lag
        squint = _vec({"eyeSquint": 0.15 * peak})
        _add(x, t, s, close, hold, opening, peak * np.eye(52)[left] + squint)
        weight = peak * rng.uniform(0.93, 1.03) * np.eye(52)[right]
        _add(x, t, s + offset, close, hold, opening, weight)


def _gaze(x: np.ndarray, t: np.ndarray, rng: np.random.Generator) -> None:
    """Fixations of 0.3-3 s joined by saccades of 20 ms + 80 ms per unit of amplitude.

    Horizontal h > 0 looks to the performer's left: eyeLookOutLeft and eyeLookInRight;
    h < 0: eyeLookInLeft and eyeLookOutRight. Vertical v > 0: eyeLookUp, v < 0: eyeLookDown
    (which also lowers the lids a little, as ARKit reads it).
    """
    starts = _events(t[-1], rng.uniform(0.5, 1.5), rng)
    k = len(starts) + 1
    spread = rng.uniform(0.15, 0.35)
    h = np.clip(rng.normal(0.0, spread, k), -0.8, 0.8)
    v = np.clip(rng.normal(-0.05, 0.6 * spread, k), -0.6, 0.6)
    home = rng.random(k) < 0.35  # back to the interlocutor
    h[home], v[home] = h[home] * 0.2, v[home] * 0.2
    amp = np.hypot(np.diff(h), np.diff(v))
    dur = 0.02 + 0.08 * amp  # s, main sequence: larger saccades take longer
    i = np.searchsorted(starts, t, side="right")  # (N,) saccades begun so far
    j = np.maximum(i - 1, 0)
    u = np.zeros_like(t)
    if len(starts):  # saccade j moves from fixation j to j + 1
        u = np.where(i > 0, _smoothstep((t - starts[j]) / dur[j]), 0.0)
    hh = h[i - (i > 0)] + (h[i] - h[i - (i > 0)]) * u
    vv = v[i - (i > 0)] + (v[i] - v[i - (i > 0)]) * u
    gain_l, gain_r = rng.uniform(0.9, 1.1, 2)
    # Fixational drift and small pursuit: 3 sines of 0.3-3 Hz, 0.01-0.04 each.
    wander = rng.uniform(0.01, 0.04, (2, 3)) * np.sin(
        2.0 * np.pi * rng.uniform(0.3, 3.0, (2, 3)) * t[:, None, None]
        + rng.uniform(0, 2 * np.pi, (2, 3))
    )  # (N, 2, 3)
    hh, vv = hh + wander[:, 0].sum(1), vv + wander[:, 1].sum(1)
    gain = dict(zip(("Left", "Right"), rng.uniform(0.9, 1.1, 2), strict=True))
    for side in ("Left", "Right"):
        toward, away = ("Out", "In") if side == "Left" else ("In", "Out")
        x[:, INDEX[f"eyeLook{toward}{side}"]] += np.maximum(hh, 0.0) * gain[side]
        x[:, INDEX[f"eyeLook{away}{side}"]] += np.maximum(-hh, 0.0) * gain[side]
        x[:, INDEX[f"eyeLookUp{side}"]] += np.maximum(vv, 0.0) * gain[side]
        x[:, INDEX[f"eyeLookDown{side}"]] += np.maximum(-vv, 0.0) * gain[side]
    down = np.maximum(-vv, 0.0)[:, None] * 0.25
    x[:, [INDEX["eyeBlinkLeft"], INDEX["eyeBlinkRight"]]] += down


# Mouth shapes a syllable can take (weights at full opening); the jaw scales them.
_VISEMES = [
    {"jawOpen": 1.0, "mouthLowerDown": 0.8, "mouthUpperUp": 0.3, "mouthStretch": 0.2,
     "jawForward": 0.1, "cheekSquint": 0.1},  # a
    {"jawOpen": 0.5, "mouthFunnel": 0.9, "mouthPucker": 0.7, "mouthLowerDown": 0.2},  # o, u
    {"jawOpen": 0.5, "mouthStretch": 0.6, "mouthSmile": 0.2, "mouthDimple": 0.3,
     "mouthUpperUp": 0.4},  # e, i
    {"jawOpen": 0.2, "mouthClose": 0.5, "mouthPress": 0.6, "mouthRollLower": 0.3,
     "mouthRollUpper": 0.3},  # m, b, p
    {"jawOpen": 0.25, "mouthRollLower": 0.7, "mouthUpperUp": 0.5, "mouthShrugUpper": 0.3},  # f, v
]  # fmt: skip
_VISEME_P = np.array([0.35, 0.2, 0.25, 0.12, 0.08])


def _speech(x: np.ndarray, t: np.ndarray, rng: np.random.Generator) -> None:
    """Phrases of 1.5-5 s separated by pauses; syllables at 3-6 Hz within a phrase."""
    talk = rng.uniform(0.2, 0.8)  # share of the take spent speaking, roughly
    shapes = [[_vec(v, a, b) for v in _VISEMES] for a, b in rng.uniform(0.9, 1.1, (4, 2))]
    now = rng.uniform(0.0, 2.0)
    while now < t[-1]:
        length = rng.uniform(1.5, 5.0)
        rate = rng.uniform(3.0, 6.0)  # Hz
        loud = rng.uniform(0.4, 1.0)
        side = shapes[rng.integers(len(shapes))]
        s = now
        while s < now + length:
            gap = rng.uniform(0.7, 1.3) / rate
            dur = 1.2 * gap
            kind = rng.choice(len(_VISEMES), p=_VISEME_P)
            amp = loud * rng.uniform(0.15, 0.6)
            _add(x, t, s, 0.4 * dur, 0.1 * dur, 0.5 * dur, amp * side[kind])
            if rng.random() < 0.08:  # emphasis on the brows
                brow = _vec({"browInnerUp": 0.6, "browOuterUp": 0.4}) * rng.uniform(0.2, 0.6)
                _add(x, t, s, 0.1, 0.15, 0.3, brow)
            s += gap
        now += length + rng.uniform(0.3, 3.0) * (1.0 - talk) / talk


_EXPRESSIONS = [
    {"mouthSmile": 1.0, "cheekSquint": 0.5, "eyeSquint": 0.3, "mouthDimple": 0.2},
    {"mouthFrown": 0.9, "browDown": 0.5, "mouthShrugLower": 0.4, "mouthPress": 0.3},
    {"browInnerUp": 1.0, "browOuterUp": 0.9, "eyeWide": 0.4},
    {"browInnerUp": 0.9, "browDown": 0.2, "mouthStretch": 0.3},
    {"eyeSquint": 0.9, "cheekSquint": 0.6, "browDown": 0.5},
    {"noseSneer": 0.9, "mouthUpperUp": 0.5, "browDown": 0.3},
    {"mouthPucker": 0.9, "mouthFunnel": 0.3},
    {"cheekPuff": 0.8, "mouthClose": 0.3},
    {"mouthRollLower": 0.7, "mouthRollUpper": 0.5, "mouthPress": 0.4},
    {"jawOpen": 0.5, "browInnerUp": 0.9, "browOuterUp": 0.8, "eyeWide": 0.8},
    {"mouthLeft": 0.6, "jawLeft": 0.2},
    {"mouthRight": 0.6, "jawRight": 0.2},
    {"jawForward": 0.5, "mouthShrugLower": 0.3},
    {"mouthSmileLeft": 0.8, "cheekSquintLeft": 0.3},
]  # fmt: skip


def _expressions(x: np.ndarray, t: np.ndarray, rng: np.random.Generator) -> None:
    """An expression every 2-6 s: onset 0.15-0.6 s, hold 0.3-3 s, release 0.3-1.2 s."""
    for s in _events(t[-1], rng.uniform(2.0, 6.0), rng):
        spec = _EXPRESSIONS[rng.integers(len(_EXPRESSIONS))]
        left, right = rng.uniform(0.85, 1.15, 2)
        w = _vec(spec, left, right) * rng.uniform(0.2, 0.9)
        _add(x, t, s, rng.uniform(0.15, 0.6), rng.uniform(0.3, 3.0), rng.uniform(0.3, 1.2), w)
