"""Where each prompt of the guided script is in a take: dynamic time warping.

A person is late, slow and uneven, so the script's timetable is not the take's. The take's
readings r (N, 52): what the tracker itself reads, as ARKit weights (MediaPipe's raw
scores, not the shipped cleaner's output: the cleaner can shrink a channel the tracker
shows, or hold one up after its prompt: dressed 29's brows), and the script's weights w
are both resampled at ``RATE`` Hz and each channel the script moves is scaled to its own
range (the take's: its robust rest ``base`` = median and top = HIGH-th percentile, the
range at least ``FLOOR``, so a face that reads a channel weakly still aligns, and a still
face's noise is not blown up):

    C[i, j] = 1 - cos([w(i), REST (1 - max w(i))], [r(j)+, REST (1 - max r(j)+)])   script i, take j
    D[i, j] = C[i, j] + min(D[i-1, j-1], D[i-1, j-2], D[i-1, j-3], D[i-2, j-1] + C[i-1, j])

Every script frame is matched once; the take may run from half to three times the
script's speed, varying along it. The path starts anywhere in the take (a late start)
and ends anywhere (the take runs on). A prompt's segment is the take time its start and
end map to. It was **seen** when, in its segment (padded by ``PAD`` s), the mean over its
channels the tracker reads of their rise above the take's rest (the median over the first
neutral hold's segment) reaches the prompt's bar at its 90th percentile and follows the
prompt's envelope (correlation at least ``CORR``). The bar is calibration's test of a
channel that moved: max(MOVE_MIN = 0.01, NOISE_K = 6 x the robust standard deviation
(1.4826 MAD) of that same mean over the neutral hold). The speech line, whose shapes are a
guess, needs only mouth movement: a mouth or jaw channel's standard deviation in its
segment at least that channel's bar. The take **follows** the script when at least
``FOLLOW`` of the prompts were seen.

A tracker does not read some channels however far the face moves them (guided/reading.py:
MediaPipe's jawLeft/Right/Forward, cheekPuff, mouthFrown, noseSneer...). A prompt aimed
only at such channels cannot be seen in its take, so, when it is not seen, it is **placed
by timing**: the take between its neighbours (the nearest prompts not placed) is taken to
run at an even pace, from the end of the one before to the start of the one after. It is
not counted against the take: the take follows the script when ``FOLLOW`` of the prompts
the tracker can show were seen (a still or random take still does not); it is not used
in the fit. A face lost there is still "face lost".
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from faceclean.calibration import MOVE_MIN, NOISE_K
from faceclean.channels import ARKIT52, GROUPS
from faceclean.errors import FacecleanError
from faceclean.guided import reading
from faceclean.guided.script import Prompt, Script

RATE = 10.0  # Hz, the alignment's grid
REST = 1.0  # weight of the rest component in the cost's vectors
FLOOR = 0.1  # weight units: the least range a channel is scaled by
HIGH = 99.5  # percentile, a channel's top in the take
PAD = 0.3  # s either side of a prompt's segment, for the seen test
MIN_HOLD = 5  # grid points of the neutral hold needed to measure its rest and noise
CORR = 0.5
FOLLOW = 0.6  # fraction of prompts seen for the take to follow the script
MIN_SPEED, MAX_SPEED = 1 / 3, 2.0  # the take's speed against the script's (the steps')
SHORT = 0.9  # a take with less face than this of the script's length is said to be short
MAX_LOST = 0.3  # a prompt whose segment lost more of its frames than this is "face lost"
_MOUTH = tuple(ARKIT52.index(n) for n in (*GROUPS["mouth"], *GROUPS["jaw"]))


@dataclass(frozen=True)
class Segment:
    prompt: Prompt
    t0: float  # s, take time of the prompt's start
    t1: float  # s, ... and of its end
    seen: bool
    why: str  # "seen", "not performed", "face lost", "placed by timing (...)"
    rise: float  # weight units, the readings' rise over rest on the prompt's channels
    corr: float  # with the prompt's envelope
    readable: bool = True  # the tracker reads at least one of the prompt's channels
    bar: float = MOVE_MIN  # weight units, the least rise that is movement (from the hold)

    @property
    def placed(self) -> bool:
        """Not seen because the tracker cannot show it: placed by timing (module docstring)."""
        return not self.readable and not self.seen and self.why != "face lost"


@dataclass(frozen=True)
class Alignment:
    script_s: np.ndarray  # (P,) s, script times along the path ...
    take_s: np.ndarray  # (P,) s, ... and the take times they map to (both increasing)
    segments: tuple[Segment, ...]
    cost: float  # mean C along the path
    tracker: str = "arkit"  # whose readings (guided/reading.py)
    short: tuple[float, float] | None = None  # s: the take's face and the script, if SHORT
    absent: tuple[str, ...] = ()  # channels the take has no value of (as if unread)

    @property
    def seen(self) -> int:
        return sum(s.seen for s in self.segments)

    @property
    def placed(self) -> int:
        return sum(s.placed for s in self.segments)

    def rests_only(self) -> Alignment:
        """This alignment with only its neutral holds seen (a fit on the face's rests)."""
        keep = tuple(g if not g.prompt.channels else replace(g, seen=False)
                     for g in self.segments)  # fmt: skip
        return replace(self, segments=keep)

    @property
    def follows(self) -> bool:
        """At least FOLLOW of the prompts the tracker can show were seen, one of them more
        than a neutral hold."""
        shown = [g for g in self.segments if g.readable]
        asked = any(g.seen and g.prompt.channels for g in shown)  # not its neutral holds alone
        return asked and sum(g.seen for g in shown) >= FOLLOW * len(shown)

    @property
    def fitted_from(self) -> str:
        """What a calibration from this take is fitted on (guided/fit.py ``guided``)."""
        return "the prompts seen" if self.follows else "its neutral holds alone"

    def shortfall(self) -> str | None:
        """Why the take falls short of the script, in one line (None: every prompt seen or
        placed by timing)."""
        missing = [g for g in self.segments if not g.seen and not g.placed]
        said = None
        if not self.follows:
            shown = [g for g in self.segments if g.readable]
            hidden = len(self.segments) - len(shown)
            aside = f"; {hidden} more that {reading.label(self.tracker)} does not read"
            aside += " or the take has no channels of" if self.absent else ""
            said = (f"the take did not follow the script ({sum(g.seen for g in shown)} of "
                    f"{len(shown)} prompts seen{aside if hidden else ''})")  # fmt: skip
        elif missing:
            names = ", ".join(f"{g.prompt.id} ({g.why})" for g in missing)
            said = f"{len(missing)} prompt{'s' * (len(missing) > 1)} not seen: {names}"
        if said and self.short:  # the likelier reason first
            said = (f"the take ({self.short[0]:.1f} s of face) is shorter than the script "
                    f"({self.short[1]:.1f} s): {said}")  # fmt: skip
        return said

    def script_time(self, t: np.ndarray) -> np.ndarray:
        """Script time (s) of take times ``t`` (NaN outside the aligned span)."""
        t = np.asarray(t, dtype=np.float64)
        s = np.interp(t, self.take_s, self.script_s)
        return np.where((t < self.take_s[0]) | (t > self.take_s[-1]), np.nan, s)


def align(
    times: np.ndarray, readings: np.ndarray, script: Script, tracker: str = "arkit"
) -> Alignment:
    """Align a take (times (N,) s, ``tracker``'s own readings (N, 52) as ARKit weights, NaN
    rows: no face) to ``script``; the tracker's unread channels (guided/reading.py) are
    left out of the seen test where a prompt aims at others, and decide which prompts
    are placed."""
    times = np.asarray(times, dtype=np.float64)
    readings = np.asarray(readings, dtype=np.float64)
    ok = np.isfinite(times) & np.isfinite(readings).any(axis=1)
    if ok.sum() < 2:
        raise FacecleanError("guided calibration: the take has no frames with a face")
    if np.any(np.diff(times[np.isfinite(times)]) <= 0):
        raise FacecleanError("guided calibration: the take's times do not increase")
    span = times[ok][-1] - times[ok][0]
    if span < script.seconds / MAX_SPEED:  # no path fits the script in it
        raise FacecleanError(
            f"guided calibration: the take ({span:.1f} s of face) is shorter than the script "
            f"({script.seconds:.1f} s) at twice its pace: record the whole script"
        )
    grid = np.arange(times[ok][0], times[ok][-1] + 1e-9, 1.0 / RATE)  # (J,) s
    x = np.nan_to_num(readings[ok])
    r = np.stack([np.interp(grid, times[ok], x[:, c]) for c in range(x.shape[1])], axis=1)
    lost = _lost(grid, times[ok])  # (J,) bool: no face within a frame's reach
    st = np.arange(int(script.seconds * RATE) + 1) / RATE  # (I,) s
    w = script.weights(st)
    have = np.isfinite(readings[ok]).any(axis=0)  # (52,) the take has a value of it
    absent = {n for n, c in zip(ARKIT52, have, strict=True) if not c}  # as if not read
    unread = set(reading.unread(tracker)) | absent
    shows = np.array([n not in unread for n in ARKIT52])  # (52,) the tracker reads it
    moved = np.flatnonzero(w.max(axis=0) > 0)
    if not len(moved):  # every target 0: nothing to find the prompts by
        raise FacecleanError("guided calibration: the script aims at no channel above 0")
    base, scale = _levels(r)
    rn = (r[:, moved] - base[moved]) / scale[moved]
    wn = w[:, moved] / w[:, moved].max(axis=0)
    cost = _cost(wn, np.clip(rn, -0.5, 1.5))  # (I, J)
    path_i, path_j = _dtw(cost)
    script_s, take_s = st[path_i], grid[path_j]  # script_s increasing, take_s not decreasing
    spans = [np.interp([p.start, p.end], script_s, take_s) for p in script.prompts]
    h0, h1 = spans[0]  # the first prompt is a neutral hold (script.from_dict)
    hold = (grid >= h0) & (grid <= h1) & ~lost
    rest = np.median(r[hold], axis=0) if hold.sum() >= MIN_HOLD else base
    segs = []
    moves = [bool(p.channels) for p in script.prompts]
    for k, (p, (t0, t1)) in enumerate(zip(script.prompts, spans, strict=True)):
        # padded, but never into the next or the last prompt that moves (two blinks 0.2 s
        # apart: the second's closure is no evidence of the first, nor its absence)
        lo, hi = t0 - PAD, t1 + PAD
        if k > 0 and moves[k - 1]:
            lo = max(lo, spans[k - 1][1])
        if k + 1 < len(spans) and moves[k + 1]:
            hi = min(hi, spans[k + 1][0])
        g = _judge(p, float(t0), float(t1), grid, r, rest, hold, lost, shows, (lo, hi))
        readable = not p.channels or bool(p.keys) or not set(p.channels) <= unread
        segs.append(replace(g, readable=readable))
    take_s, segs = _place(script_s, take_s, segs, reading.label(tracker), absent)
    keep = np.r_[True, np.diff(take_s) > 0]  # one script time per take time: increasing
    cost_mean = float(cost[path_i, path_j].mean())
    short = span < SHORT * script.seconds
    return Alignment(script_s[keep], take_s[keep], tuple(segs), cost_mean, tracker,
                     (span, script.seconds) if short else None, tuple(sorted(absent)))  # fmt: skip


def _place(
    script_s: np.ndarray, take_s: np.ndarray, segs: list[Segment], tracker: str,
    absent: set[str],
) -> tuple[np.ndarray, list[Segment]]:  # fmt: skip
    """The path (take times of ``script_s``) and segments with each prompt the tracker
    cannot show (or whose channels the take has none of: ``absent``), and did not, placed
    at an even pace between its neighbours."""
    placed = [g.placed for g in segs]
    span = np.zeros(len(script_s), bool)  # (P,) path points to place by timing
    for k in np.flatnonzero(placed):
        before = [i for i in range(k) if not placed[i]]
        after = [i for i in range(k + 1, len(segs)) if not placed[i]]
        if before and after:  # else the alignment's own (no neighbour to time from)
            lo, hi = segs[before[-1]].prompt.end, segs[after[0]].prompt.start
            span |= (script_s > lo) & (script_s < hi)
    if span.any() and not span.all():
        take_s = take_s.copy()
        take_s[span] = np.interp(script_s[span], script_s[~span], take_s[~span])
    out = []
    for g in segs:
        if g.placed:
            t0, t1 = np.interp([g.prompt.start, g.prompt.end], script_s, take_s)
            names = ", ".join(g.prompt.channels)
            why = (f"placed by timing (the take has no {names})"
                   if set(g.prompt.channels) <= absent
                   else f"placed by timing ({tracker} does not read {names})")  # fmt: skip
            g = replace(g, t0=float(t0), t1=float(t1), why=why)
        out.append(g)
    return take_s, out


def _levels(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(base, scale) (52,): each channel's rest (median) and range (at least FLOOR)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        base = np.median(r, axis=0)
        top = np.percentile(r, HIGH, axis=0)
    return base, np.maximum(top - base, FLOOR)


def _lost(grid: np.ndarray, t_ok: np.ndarray) -> np.ndarray:
    """(J,) bool: the nearest frame with a face is farther than 2 of the take's frames."""
    dt = float(np.median(np.diff(t_ok))) if len(t_ok) > 1 else 1.0
    k = np.clip(np.searchsorted(t_ok, grid), 1, len(t_ok) - 1)
    near = np.minimum(np.abs(grid - t_ok[k - 1]), np.abs(t_ok[k] - grid))
    return near > 2.5 * dt


def _cost(wn: np.ndarray, rn: np.ndarray) -> np.ndarray:
    """(I, J) cosine distances between script rows and take rows, each with a rest
    component (``REST`` times how far the row is from any movement): scale-free, so a
    face that reads weakly aligns, and a neighbour the tracker moves along costs little."""
    rp = np.clip(rn, 0.0, 1.5)
    w = np.c_[wn, REST * (1.0 - np.clip(wn.max(axis=1), 0.0, 1.0))]
    r = np.c_[rp, REST * (1.0 - np.clip(rp.max(axis=1), 0.0, 1.0))]
    w /= np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-9)
    r /= np.maximum(np.linalg.norm(r, axis=1, keepdims=True), 1e-9)
    return 1.0 - w @ r.T


def _dtw(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The module's recurrence over cost (I, J): the path as (I,) script and take indices."""
    n_i, n_j = c.shape
    inf = np.inf
    d = np.full((n_i, n_j), inf)
    step = np.zeros((n_i, n_j), dtype=np.int8)  # 0..2: (1, 1..3); 3: (2, 1)
    d[0] = c[0]  # open begin: the script may start at any take frame
    for i in range(1, n_i):
        prev = d[i - 1]
        opts = np.full((4, n_j), inf)
        for k in (1, 2, 3):
            opts[k - 1, k:] = prev[:-k]
        if i >= 2:
            opts[3, 1:] = d[i - 2, :-1] + c[i - 1, 1:]
        step[i] = np.argmin(opts, axis=0)
        d[i] = c[i] + opts[step[i], np.arange(n_j)]
    j = int(np.argmin(d[-1]))  # open end
    if not np.isfinite(d[-1, j]):
        raise FacecleanError(
            "guided calibration: the take is too short to hold the script even at "
            f"{MAX_SPEED:g}x its speed"
        )
    ii, jj = [n_i - 1], [j]
    i = n_i - 1
    while i > 0:
        s = int(step[i, j])
        if s < 3:
            i, j = i - 1, j - (s + 1)
            ii.append(i)
            jj.append(j)
        else:
            ii += [i - 1, i - 2]
            jj += [j, j - 1]
            i, j = i - 2, j - 1
    return np.array(ii[::-1]), np.array(jj[::-1])


def _judge(
    p: Prompt, t0: float, t1: float, grid: np.ndarray, r: np.ndarray, rest: np.ndarray,
    hold: np.ndarray, lost: np.ndarray, shows: np.ndarray, window: tuple[float, float],
) -> Segment:  # fmt: skip
    """The prompt's segment, and whether the take shows it in ``window`` (s: the segment
    padded, module docstring)."""
    inside = (grid >= window[0]) & (grid <= window[1])
    if not inside.any():
        return Segment(p, t0, t1, False, "not performed", 0.0, 0.0)
    if lost[inside].mean() > MAX_LOST:
        return Segment(p, t0, t1, False, "face lost", 0.0, 0.0)
    if not p.channels:  # a neutral hold: seen unless the face is lost
        return Segment(p, t0, t1, True, "seen", 0.0, 1.0)
    if p.keys:  # speech: mouth movement is enough (its shapes are a guess)
        cols = [c for c in _MOUTH if shows[c]] or list(_MOUTH)
        moves = np.std(r[inside][:, cols], axis=0)  # (C,)
        bars = _bar(r[hold][:, cols], axis=0)
        k = int(np.argmax(moves / bars))
        seen = bool(moves[k] >= bars[k])
        why = "seen" if seen else "not performed"
        return Segment(p, t0, t1, seen, why, float(moves[k]), 0.0, bar=float(bars[k]))
    aimed = [ARKIT52.index(n) for n in p.channels]
    cols = [c for c in aimed if shows[c]] or aimed  # what the tracker reads of it, if any
    # the script's time of each grid point in the segment, linear in the take
    u = (grid[inside] - t0) / max(t1 - t0, 1e-9) * p.duration
    env = p.weights(u)[:, cols].sum(axis=1)  # (K,) the envelope
    rise = (r[inside][:, cols] - rest[cols]).mean(axis=1)  # (K,) the channels' mean rise
    bar = float(_bar((r[hold][:, cols] - rest[cols]).mean(axis=1)))  # ... its hold's noise
    top = float(np.percentile(rise, 90))
    corr = _corr(env, rise)
    seen = top >= bar and corr >= CORR
    return Segment(p, t0, t1, seen, "seen" if seen else "not performed", top, corr, bar=bar)


def _bar(quiet: np.ndarray, axis: int | None = None) -> np.ndarray:
    """The least rise that is movement: max(MOVE_MIN, NOISE_K x the robust standard
    deviation (1.4826 MAD) of ``quiet``, the neutral hold's readings); MOVE_MIN alone
    without a hold."""
    if quiet.shape[0] < MIN_HOLD:
        return np.full(quiet.shape[1:] if axis == 0 else (), MOVE_MIN)
    mad = np.median(np.abs(quiet - np.median(quiet, axis=axis)), axis=axis)
    return np.maximum(MOVE_MIN, NOISE_K * 1.4826 * mad)


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 0 else 0.0
