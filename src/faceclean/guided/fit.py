"""Guided calibration: fit a per-face adaptation of the cleaner from the script's take.

``guided(anim, tracker)`` aligns the take to the script (guided/align.py) and fits:

- ``mediapipe``: the shipped MediaPipe cleaner runs on the take (its output y, (N, 52)).
  The aligned frames of the prompts seen give targets T = the script's weights at each
  frame's script time (the speech line, whose shapes are a guess, has weight 0). Per
  channel group G (``channels.GROUPS``: where the tracker mixes channels), the change is
  pivoted on the face's rest reading r (the median of y over the script's opening neutral
  hold, before any prompt has moved the cleaner's own rest), so a neutral face reads as
  the shipped cleaner says (which is its best guess there: the tracker barely tells a rest
  from a low level), and only excursions are rescaled. (Pivoted on all the script's rests,
  which the cleaner reads higher once a prompt has pushed its stream rest down, a face
  held neutral came out up to 0.23 off: docs/CALIBRATION.md "A still face")::

      y' = y + D_G (y_G - r_G)
      D_G[k] = argmin sum_n v_n (T_nk - y_nk + r_k - D_G[k] (y_nG - r_G))^2
                      + LAMBDA_G * n * sum_i (var_i + V_i) D_G[k, i]^2

  a ridge toward the identity (D = 0: the shipped model alone) scaled by each input's
  own variance, V_i = V0 for the channel's own input and V_CROSS for a neighbour (a
  neighbour must move clearly to correct a channel); the groups are FIT_GROUPS (the
  eyes' gaze apart from their lids), each shrunk by its own LAMBDA_G (LAMBDAS). A
  channel no seen prompt aims at is not touched, nor are the squint's and the wide eyes'
  (UNFITTED); a channel that did not move (a still face) keeps D near 0. The result is
  ``faceclean.adaptation.Adaptation`` (after the cleaner), with offsets c = -D r.
  With it, the face's own resting reading of the mouth's and the gaze's inputs
  (REST_INPUTS: u, as the cleaner's pre-filter gives it, the median over all the
  script's rests: u, unlike y, does not depend on the stream rest a prompt pushed down):
  the cleaner then measures the mouth's, the cheeks' and the gaze's rises (REST_OUTPUTS)
  from the lower of it and the stream's own rest, so a mouth a performer holds slightly
  set from the first frame reads as set, not as a rest, and eyes that look down at a
  phone for a whole take read as looking down, not ahead (learned/tracker_map.py
  ``set_rest_reading``). Where the brows read the script better as their own rise alone
  than through the map's rows (guided/own.py), the map reads them so for this face
  (``Adaptation.own``, ``set_own_rise``) and D leaves them alone.
- ``arkit``: per-channel levels before the cleaner (faceclean.adjust, as ``calibrate``
  writes): neutral = median over the neutral holds; a channel that a seen prompt aims at
  (target v) and that rose there maps the HOLD_Q-th percentile of its hold onto v (gain
  capped at calibration.MAX_GAIN); any other channel keeps its range ([neutral, 1] onto
  [0, 1]). Blinks: their prompts are blinks, so a blink seen reaches full closure.

Nothing here prints; the command (cli/calibrate.py) reports per prompt.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import nnls

from faceclean.adaptation import Adaptation, fitted_after
from faceclean.adjust import Adjust
from faceclean.animation import MAX_ABS, Animation
from faceclean.calibration import MAX_GAIN, MOVE_MIN
from faceclean.channels import ARKIT52, GROUPS, TRACKERS
from faceclean.errors import FacecleanError
from faceclean.guided import align as al
from faceclean.guided.own import choose
from faceclean.guided.script import Script, load

LAMBDA = 10.0  # ridge on D relative to each input's own variance (+ V0): scale-free, so
# a channel one prompt moves a little is fitted as surely as one that moves much. A
# script's levels carry poorly to speech, so the fit moves little: pivoted on the opening
# neutral, on the four faces chosen on (painted 7, dressed 5, photo 47, obama3 53) the mean
# guided / uncalibrated MSE is 0.946 / 0.931 / 0.922 / 0.911 / 0.902 / 0.901 at LAMBDA
# 1 / 2 / 3 / 5 / 10 / 30 (no D: 0.907); 10 for its blinks (docs/CALIBRATION.md).
# Per group (FIT_GROUPS), chosen on those four faces (mean guided / shipped-fit MSE, each
# group's LAMBDA from 0.1-100 with the others at 10; a group moved only where that gains
# over 0.5 % and takes no face's group further above raw): the brows 0.3 (0.994); the
# lids, jaw, mouth and cheeks within 0.3 % of 10 (docs/CALIBRATION.md, "Shrunk by group").
# The gaze, free, took photographed faces' gaze further above raw at any LAMBDA under 10;
# only lifted (ADD_ONLY) it gains on all six faces chosen on, and 1 is the least that
# leaves a still face within 0.01 of the uncalibrated cleaner's (0.1 / 0.3: dressed 37
# 0.015 / 0.013 higher): docs/CALIBRATION.md, "The gaze only lifted".
# Outputs the fit leaves as the shipped cleaner reads them: the squint and wide-eyed
# prompts' levels do not carry to a talking face. Their rows of D made the lids worse than
# uncalibrated on all ten faces measured; without them guided MSE is lower on the eight
# judged (biden 0.492 -> 0.476), and blink closure is kept (docs/CALIBRATION.md, "The
# lids' rows").
UNFITTED = tuple(n for n in GROUPS["eyes"] if n.startswith(("eyeSquint", "eyeWide")))
GAZE = tuple(n for n in GROUPS["eyes"] if n.startswith("eyeLook"))
# The groups D mixes within: channels.GROUPS, the gaze apart from the lids (a lid's
# reading is no evidence of where an eye looks, nor the other way round).
FIT_GROUPS = {"lids": tuple(n for n in GROUPS["eyes"] if n not in GAZE), "gaze": GAZE,
              **{g: m for g, m in GROUPS.items() if g != "eyes"}}  # fmt: skip
LAMBDAS = {"brows": 0.3, "gaze": 1.0}  # a group's own LAMBDA (LAMBDA where not named)
# Groups whose rows only add (D >= 0, a non-negative ridge): the gaze. A script's frames
# that aim at no look hold the face's resting reading of one (a photographed face reads
# eyeLookUp 0.2 at rest), which a free fit takes down, and with it a look a performer
# holds; lifting a look the tracker reads short is what carries (docs/CALIBRATION.md,
# "The gaze only lifted").
ADD_ONLY = ("gaze",)
V0 = 1e-4  # weight units^2: the tracker's noise floor, so a still channel is not trusted
V_CROSS = 0.01  # weight units^2: a neighbour must move about 0.1 to correct a channel
MAX_OFFSET = 0.3
MAX_COEF = 2.0
HOLD = 0.8  # the part of a prompt whose envelope is above this is its hold
HOLD_Q = 75.0  # percentile of a channel over its holds, taken as the level it reached
# A face's rest reading (module docstring): of the mouth's inputs, for the mouth's and the
# cheeks' outputs. On three faces chosen on (painted:7, dressed:5, photo:47:obama) every
# input for every output did best; on the four faces of docs/CALIBRATION.md it took
# photographed faces' jaw and brows above raw (a photograph's brows and lids read their
# own rest), where the mouth alone gained on all seven and on three more rendered after
# the choice (docs/CALIBRATION.md, "The rest reading"). Gaze too, each look from its own
# reading (the map reads gaze as its own rise): where a performer looks somewhere for a
# whole take the stream's rest holds the look, and the neutral ("look straight ahead")
# does not; better on all ten faces, guided and from a neutral hold alike ("Gaze").
REST_INPUTS = GROUPS["mouth"] + GAZE
# The face's own closure (``Adaptation.closure``): where its closed eyes, the script's
# blinks and eyes closed alone, read ``top`` after D, short of CLOSED, each blink output is
# lifted from CLOSE_KNEE of the way from its rest to that top, so the face's own closure
# reads 1 and its narrowings (below the knee) as they were (docs/CALIBRATION.md,
# "The face's own closure"). The shipped map cannot: MediaPipe reads a closing eye and a
# narrowing one on one scale, which differs by face (docs/MODEL.md, 22nd round).
# Chosen on the four faces of LAMBDA's choice: from half way (0.5) their blinks close
# 0.81 / 0.62 / 0.55 / 0.68 -> 0.85 / 0.84 / 0.55 / 0.87 with every lids group under raw;
# from 0.3 dressed 5's lids go over raw (1.02x), from 0.7 they close less; obama's closed
# eyes read 0.3 (a slope of 6-7), and lifted its blinks overshot (closure 1.47, lids
# 0.48 -> 0.74x raw), so a slope over CLOSE_GAIN lifts none.
# A blink (100-300 ms) comes out of the cleaner short of the level a held closure reads
# (the map's band smooths it), so the closure read as 1 is CLOSE_AIM of the way from the
# knee to the holds' top. Chosen on the six faces chosen on (painted 7, 31, dressed 5, 37,
# photo 47, 53) by the mean |log closure| of the four it lifts: 0.13 / 0.11 / 0.10 / 0.11
# at 1 / 0.9 / 0.8 / 0.7, every face's MSE within 0.001 (docs/CALIBRATION.md, "The face's
# own closure").
BLINKS = ("eyeBlinkLeft", "eyeBlinkRight")
CLOSE_AIM = 0.8
CLOSE_KNEE = 0.5
CLOSED = 0.95
CLOSE_MIN = 0.1  # weight units: an eye whose closure rose less was not seen closing
CLOSE_GAIN = 4.0  # the lift's slope 1 / (top - knee) at most, else none
# Outputs that measure their rises from the face's rest reading: the mouth's, cheeks' and
# gaze's, but for four whose rest reading made them worse on the six faces chosen on (by
# over 0.002 of raw MSE, summed: dimples 0.018 / 0.010, shrugUpper 0.005, rollLower 0.004;
# docs/CALIBRATION.md, "The rest reading left off four mouth outputs").
REST_LEFT = ("mouthDimpleLeft", "mouthDimpleRight", "mouthShrugUpper", "mouthRollLower")
REST_OUTPUTS = tuple(n for n in GROUPS["mouth"] + GROUPS["cheeks_nose"] + GAZE
                     if n not in REST_LEFT)  # fmt: skip


@dataclass(frozen=True)
class Guided:
    """What a guided calibration found and fitted."""

    adjust: Adjust  # the calibration file's content (levels and/or adaptation)
    alignment: al.Alignment
    before: dict[str, float]  # prompt id -> mean peak of its channels, uncalibrated
    after: dict[str, float]  # ... calibrated (the same frames)
    target: dict[str, float]  # ... the script's aim
    tracker: str


def shipped_cleaner(tracker: str, names: tuple[str, ...]):
    """(a fresh shipped cleaner for ``tracker`` over ``names``, its description)."""
    from faceclean.resolve import resolve, tracker_words

    words = tracker_words(tracker)
    choice = resolve(words)
    return choice.build(names), fitted_after(words) or choice.source


def response(anim: Animation, tracker: str) -> tuple[np.ndarray, np.ndarray, str, Any]:
    """(y (N, 52) ARKit weights NaN where absent, present (52,) bool, cleaner label, the
    cleaner): what the guided fit sees: the shipped cleaner's output for MediaPipe, the
    values for ARKit (no cleaner: None)."""
    if tracker == "mediapipe":
        cleaner, label = shipped_cleaner(tracker, anim.names)
        cleaned = cleaner.clean(anim)
        y, present = cleaned.arkit()
        y = np.where(anim.valid[:, None], y, np.nan)  # a lost face is no response
        return y, present, label, cleaner
    y, present = anim.arkit()
    return y, present, "levels", None


def rest_reading(anim: Animation, cleaner: Any, at_rest: np.ndarray) -> dict[str, float]:
    """REST_INPUTS' reading at rest: u, ``cleaner``'s own pre-filter (a tracker map's One
    Euro, a copy) over ``anim``, its median over the frames ``at_rest`` (N,) bool; {}: no
    rest frames, or a cleaner with no such pre-filter."""
    import copy

    pre, w = copy.deepcopy(getattr(cleaner, "pre", None)), getattr(cleaner, "weights", None)
    if pre is None or w is None:
        return {}
    x, have = anim.arkit(w.inputs)  # (N, K) by canonical name (PascalCase too); absent: 0
    names = [n for n in REST_INPUTS if n in w.inputs and have[w.inputs.index(n)]]
    keep = at_rest & anim.valid
    if not names or not keep.any():
        return {}
    pre.reset()
    u = pre.clean(Animation(anim.times, x, tuple(w.inputs))).values
    return {n: float(np.median(u[keep, w.inputs.index(n)])) for n in names}


def rest_calibration(
    anim: Animation, neutral_s: float, facts: dict[str, Any], cleaner: Any = None
) -> Adjust:
    """A neutral calibration for the shipped MediaPipe map (or ``cleaner``, a tracker map
    of the page's choice): the face's rest reading over the first ``neutral_s`` s of
    ``anim``, and no levels (``facts``: the calibration's, marked ``"levels": "none"``).
    The map was fitted on MediaPipe's raw scores and measures rises itself: levels before
    it (the neutral subtracted, the range stretched) cost on seven of ten held-out faces
    (up to 1.20x its MSE), the reading alone gains on all ten (0.86-1.00x;
    docs/CALIBRATION.md, "A neutral hold for the map")."""
    if cleaner is None:
        cleaner, label = shipped_cleaner("mediapipe", anim.names)
    else:
        label = getattr(cleaner, "name", "tracker map")
    hold = anim.times - anim.times[0] <= neutral_s
    reading = rest_reading(anim, cleaner, hold)
    rest = (Adaptation({}, {}, "mediapipe", {"cleaner": label}, reading, REST_OUTPUTS)
            if reading else None)  # fmt: skip
    return Adjust((), {**facts, "levels": "none"}, adaptation=rest)


def guided(
    anim: Animation, tracker: str = "mediapipe", script: Script | None = None,
    take: str | None = None,
) -> Guided:  # fmt: skip
    """The guided calibration of ``anim`` (module docstring)."""
    if tracker not in TRACKERS:
        raise FacecleanError(f"guided calibration: unknown tracker {tracker!r}")
    script = script or load()
    v = anim.values
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(v) <= MAX_ABS)  # inf or past any weight: a missing cell, as NaN is
    anim = anim.with_values(np.where(bad, np.nan, v)) if bad.any() else anim
    x, present = anim.arkit()
    if not present.any():
        raise FacecleanError("guided calibration: the take has no ARKit blendshape channels")
    y, present, label, cleaner = response(anim, tracker)
    found = al.align(anim.times, np.where(present, x, np.nan), script, tracker)  # as read
    # A take that does not follow the script (--partial) is fitted on its rests alone: a
    # random take's prompts "seen" by chance fitted a D that made three faces of fifteen
    # 1.07-1.18x worse than uncalibrated; their rests alone, 0.76-0.85x
    # (docs/CALIBRATION.md, "A take that does not follow: its rests alone").
    alignment = found if found.follows else found.rests_only()
    t = anim.times
    s = alignment.script_time(t)  # (N,) s, NaN outside the aligned span
    target = script.weights(np.nan_to_num(s))  # (N, 52)
    weight = _frame_weights(alignment, t, s, target) * np.isfinite(y).all(axis=1, where=present)
    facts = {
        "take": take or "take",
        "frames": int(anim.valid.sum()),
        "tracker": tracker,
        "guided": {
            "script": script.title,
            "seen": [g.prompt.id for g in found.segments if g.seen],
            "not_seen": [g.prompt.id for g in found.segments if not g.seen],
            "placed": [g.prompt.id for g in found.segments if g.placed],  # by timing
            "follows": bool(found.follows),
        },
    }
    if tracker == "mediapipe":
        fresh, _ = shipped_cleaner(tracker, anim.names)  # the take again, some rows own
        own, y_own, facts["guided"]["own"] = choose(fresh, anim, y, target, weight, present,
                                                    alignment)  # fmt: skip
        adaptation = fit_adaptation(y_own, target, weight, present, fixed=own)
        still = (weight > 0) & (target.max(axis=1) == 0)  # the rests it was pivoted on
        reading = rest_reading(anim, cleaner, still)
        adaptation = Adaptation(adaptation.offset, adaptation.matrix, tracker, {"cleaner": label},
                                reading, REST_OUTPUTS if reading else (), own=own)  # fmt: skip
        shut = fit_closure(adaptation.apply(np.nan_to_num(y_own), ARKIT52), target, alignment,
                           t, _first_run(still))  # fmt: skip
        adaptation = replace(adaptation, closure=shut)
        adjust = Adjust((), facts, adaptation=adaptation)
        y_after = adaptation.apply(np.nan_to_num(y_own), ARKIT52)
    else:
        adjust = fit_levels(x, target, weight, alignment, anim.times, facts)
        from faceclean.adjust import apply_levels

        y_after = apply_levels(adjust.levels(ARKIT52), np.nan_to_num(x))
        y = x
    before, after, aims = _peaks(alignment, t, np.nan_to_num(y), y_after, target)
    return Guided(adjust, found, before, after, aims, tracker)


def _frame_weights(alignment: al.Alignment, t: np.ndarray, s: np.ndarray,
                   target: np.ndarray) -> np.ndarray:  # fmt: skip
    """(N,) each frame's weight in the fit: its prompt's weight if seen, else 0; a rest
    between two segments counts 1 (a frame there whose script time falls in a prompt, 0:
    it would fit a prompt not seen)."""
    w = np.where(np.isfinite(s) & (target.max(axis=1) == 0), 1.0, 0.0)
    for g in alignment.segments:
        inside = (t >= g.t0) & (t <= g.t1)
        w[inside] = g.prompt.weight if g.seen else 0.0
    return w


def fit_adaptation(
    y: np.ndarray, target: np.ndarray, weight: np.ndarray, present: np.ndarray,
    fixed: tuple[str, ...] = (),
) -> Adaptation:  # fmt: skip
    """The ridge fit of the module docstring: y, target (N, 52), weight (N,); ``fixed``
    outputs as UNFITTED are (read as their own rise)."""
    use = weight > 0
    v = weight[use][:, None]  # (n, 1)
    n = float(v.sum())
    offset: dict[str, float] = {}
    matrix: dict[str, dict[str, float]] = {}
    if n < 1:
        return Adaptation(offset, matrix)
    aimed = (target[use] > 0).any(axis=0)  # (52,) a seen prompt aims at the channel
    still = use & (target.max(axis=1) == 0)  # frames at rest: neutral holds, between prompts
    if not still.any():
        return Adaptation(offset, matrix)
    rest = np.median(y[_first_run(still)], axis=0)  # (52,) the pivot: the opening neutral
    for group, members in FIT_GROUPS.items():
        lam = LAMBDAS.get(group, LAMBDA)
        cols = [ARKIT52.index(m) for m in members if present[ARKIT52.index(m)]]
        if not cols:
            continue
        yg, eg = y[use][:, cols], (target - y)[use][:, cols]  # (n, G)
        my, me = rest[cols], -rest[cols]  # the pivot: the face at rest reads as shipped
        yc, ec = yg - my, eg - me
        var = (v * yc * yc).sum(0) / n  # (G,) each input's variance over the fit
        gram, cov = (v * yc).T @ yc, (v * yc).T @ ec  # (G, G), (G in, G out)
        d = np.zeros((len(cols), len(cols)))  # (G out, G in)
        for k in range(len(cols)):  # its own input trusted at V0, a neighbour at V_CROSS
            pen = lam * n * (var + V_CROSS)
            pen[k] = lam * n * (var[k] + V0)
            d[k] = _ridge(gram + np.diag(pen), cov[:, k], group in ADD_ONLY)
        d = np.clip(d, -MAX_COEF, MAX_COEF)
        c = np.clip(-d @ my, -MAX_OFFSET, MAX_OFFSET)  # y' = y + D (y - rest)
        for k, j in enumerate(cols):
            name = ARKIT52[j]
            if not aimed[j] or name in UNFITTED or name in fixed:  # the shipped model's output
                continue
            if abs(c[k]) > 1e-4:
                offset[name] = float(c[k])
            row = {
                ARKIT52[cols[i]]: float(d[k, i]) for i in range(len(cols)) if abs(d[k, i]) > 1e-4
            }
            if row:
                matrix[name] = row
    return Adaptation(offset, matrix)


def _ridge(a: np.ndarray, b: np.ndarray, add_only: bool) -> np.ndarray:
    """argmin_d d'a d - 2 b'd over d (a (G, G) positive definite), with d >= 0 if
    ``add_only``: as least squares ||L'd - L^-1 b||^2 with a = L L'."""
    if not add_only:
        return np.linalg.solve(a, b)
    low = np.linalg.cholesky(a)
    return nnls(low.T, np.linalg.solve(low, b))[0]


def fit_closure(y: np.ndarray, target: np.ndarray, alignment: al.Alignment, t: np.ndarray,
                rest: np.ndarray) -> dict[str, tuple[float, float]]:  # fmt: skip
    """{blink: (knee, top)} (module docstring, CLOSE_KNEE, CLOSE_AIM): the holds' top is
    the median over the seen prompts that close the eye of its HOLD_Q-th percentile over
    their holds, in y (N, 52) as corrected; the rest its median over ``rest`` (N,) bool;
    ``top`` (read as 1) CLOSE_AIM of the way from the knee to it. None where the eye was
    never seen closing, closes to CLOSED already, did not rise by CLOSE_MIN, or would need
    a slope over CLOSE_GAIN (of the holds' top)."""
    out: dict[str, tuple[float, float]] = {}
    if not rest.any():
        return out
    for name in BLINKS:
        i = ARKIT52.index(name)
        reached = [float(np.percentile(y[rows, i], HOLD_Q)) for g in alignment.segments
                   if g.seen and g.prompt.targets.get(name, 0) >= CLOSED
                   for rows in [(t >= g.t0) & (t <= g.t1) & (target[:, i] >= HOLD)]
                   if rows.any()]  # fmt: skip
        low = float(np.median(y[rest, i]))
        top = float(np.median(reached)) if reached else None
        if top is None or top >= CLOSED or top - low < CLOSE_MIN:
            continue
        knee = low + CLOSE_KNEE * (top - low)
        if 1.0 / (top - knee) <= CLOSE_GAIN:  # a steeper lift takes a narrowing for a blink
            out[name] = (knee, knee + CLOSE_AIM * (top - knee))
    return out


def _first_run(rows: np.ndarray) -> np.ndarray:
    """(N,) bool: the first run of consecutive True in ``rows`` (the script's opening
    neutral hold among its rests)."""
    out = np.zeros_like(rows)
    idx = np.flatnonzero(rows)
    if len(idx):
        gaps = np.flatnonzero(np.diff(idx) > 1)
        out[idx[0] : (idx[gaps[0]] if len(gaps) else idx[-1]) + 1] = True
    return out


def fit_levels(
    x: np.ndarray, target: np.ndarray, weight: np.ndarray, alignment: al.Alignment,
    t: np.ndarray, facts: dict,
) -> Adjust:  # fmt: skip
    """ARKit levels from the aligned prompts (module docstring)."""
    neutral_rows = np.zeros(len(t), bool)
    for g in alignment.segments:
        if g.seen and not g.prompt.channels:
            neutral_rows |= (t >= g.t0) & (t <= g.t1)
    if neutral_rows.sum() < 5:
        raise FacecleanError("guided calibration: no neutral hold seen in the take")
    hold = x[neutral_rows]
    neutral = np.nanmedian(hold, axis=0)
    noise = 1.4826 * np.nanmedian(np.abs(hold - neutral), axis=0)
    rules, chans, lifted = [], {}, []
    for i, name in enumerate(ARKIT52):
        if not np.isfinite(neutral[i]):
            continue
        nv = float(neutral[i])
        reached, aim = [], []
        for g in alignment.segments:
            if g.seen and name in g.prompt.targets:
                rows = (t >= g.t0) & (t <= g.t1) & (target[:, i] >= HOLD * g.prompt.targets[name])
                if rows.any():
                    reached.append(float(np.nanpercentile(x[rows, i], HOLD_Q)))
                    aim.append(g.prompt.targets[name])
        top = float(np.median(reached)) if reached else None
        if top is not None and top - nv > max(MOVE_MIN, 6 * float(noise[i])):
            gain = min(float(np.median(aim)) / (top - nv), MAX_GAIN)
            lifted.append(name)
        elif nv < 0.5:
            gain, top = 1.0 / (1.0 - nv), None
        else:
            nv, gain, top = 0.0, 1.0, None
        rules += [(name, "offset", nv), (name, "gain", gain)]
        rules += [(name, "curve", 1.0), (name, "clamp", (0.0, 1.0))]
        chans[name] = {
            "neutral": round(nv, 6),
            "noise": round(float(noise[i]), 6),
            "top": None if top is None else round(top, 6),
            "gain": round(gain, 6),
        }
    facts = {**facts, "lifted": lifted, "channels": chans}
    return Adjust(tuple(rules), facts)


def _peaks(alignment, t, y, y_after, target):
    """Per prompt with targets: the mean over its channels of the 90th percentile in its
    segment, before, after, and the aim."""
    before, after, aims = {}, {}, {}
    for g in alignment.segments:
        if not g.prompt.targets:
            continue
        rows = (t >= g.t0) & (t <= g.t1)
        if not rows.any():
            continue
        cols = [ARKIT52.index(n) for n in g.prompt.targets]
        before[g.prompt.id] = float(np.percentile(y[rows][:, cols], 90, axis=0).mean())
        after[g.prompt.id] = float(np.percentile(y_after[rows][:, cols], 90, axis=0).mean())
        aims[g.prompt.id] = float(np.mean(list(g.prompt.targets.values())))
    return before, after, aims
