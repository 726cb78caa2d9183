"""The one streaming contract every cleaner follows, and the rules for time.

``reset()`` forgets everything; ``step(frame, t) -> frame`` cleans one frame as it
arrives; ``clean(animation)`` is reset-then-step over the valid frames.

Frames are (M,) with a scalar t, or (S, M) with t (S,) for S streams stepped together.
Time rules, applied per stream, in this order:

1. t not finite, or every value of the frame non-finite: a missing frame. The output is
   the last output (NaN before the first frame); the state does not change.
2. Non-finite values in an otherwise good frame are replaced by the last output of
   their channel (0 before the first frame). A value beyond +-``MAX_ABS`` is a tracker
   glitch, not a weight: it counts as non-finite (so nothing overflows).
3. First frame, or a pause longer than ``max_gap`` seconds: the state restarts from this
   frame and the output equals it (the face came back; nothing jumps or drifts).
4. t not after the previous frame's time by more than ``MIN_DT`` (duplicate, backwards,
   or a subnormal step that float32 kernels cannot resolve): the last output again,
   state unchanged. ``t == 0.0`` is a valid time.
5. Otherwise the cleaner advances by dt = t - t_prev > 0 seconds.

Every ``clean`` (this class's and any subclass's own) ends in ``check_finite``: an output
that is not finite where its input was (a kalman with ``r=1e300``, a model with NaN
scales) is a FacecleanError, never a file. Paths that step a cleaner themselves (the
streaming file path, the CLI's progress loop, the relay's start-up probe) call it too.
"""

from __future__ import annotations

import functools
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import ClassVar

import numpy as np

from faceclean.animation import MAX_ABS, MIN_DT, Animation  # rules 2 and 4
from faceclean.errors import FacecleanError

State = tuple[np.ndarray, ...]  # each (S, M)
MAX_GAP = 0.5  # s; the default max_gap: a longer pause restarts the state (rule 3)
PROGRESS_EVERY = 1000  # frames between two reports to StreamCleaner.clean's progress
BLOCK = 4096  # frames a whole-take clean holds at once beside its input and output


def gap_seconds(max_gap: float) -> float:
    """A cleaner's ``max_gap`` checked: a number of seconds > 0 (NaN is refused)."""
    if not max_gap > 0:
        raise FacecleanError(f"max_gap must be > 0 s (got {max_gap})")
    return float(max_gap)


def advances(dt, max_gap: float):
    """Rules 4-5 for a frame dt s after the last accepted one (NaN: none yet), scalar or
    array: True where the state advances by dt (MIN_DT < dt <= max_gap); NaN is False."""
    return (dt > MIN_DT) & (dt <= max_gap)


def frame_rules(missing: np.ndarray, dt: np.ndarray, max_gap: float) -> tuple[np.ndarray, ...]:
    """Rules 1, 3-5 per stream: (start, advance) bool (S,) for frames that are
    ``missing`` (rule 1) or came dt (S,) s after the last accepted one (NaN: none yet).
    Neither: the frame holds (the last output, state unchanged)."""
    start = ~missing & ~(dt <= max_gap)  # rule 3 (NaN dt starts)
    return start, ~missing & advances(dt, max_gap)  # rule 4 holds the rest


def time_rules(t: np.ndarray, missing: np.ndarray, max_gap: float) -> tuple[np.ndarray, ...]:
    """``frame_rules`` over whole sequences, as stepping them frame by frame would apply
    them: t (S, T) s, missing (S, T) bool (rule 1; a non-finite t is missing too).

    Returns (start, advance, dt): (S, T) bool, bool and s since the last accepted frame
    where advancing (NaN elsewhere). Accepted times only increase, so the last accepted
    time is the running maximum of the earlier present times unless some frame lands
    within MIN_DT above that maximum (a held near-duplicate); then it loops over T.
    """
    t = np.asarray(t, dtype=np.float64)
    missing = np.asarray(missing, dtype=bool) | ~np.isfinite(t)
    seen = np.maximum.accumulate(np.where(missing, -np.inf, t), axis=1)  # (S, T)
    last = np.concatenate([np.full((len(t), 1), -np.inf), seen[:, :-1]], axis=1)
    with np.errstate(invalid="ignore"):
        dt = np.where(np.isfinite(last), t - last, np.nan)  # NaN: nothing accepted yet
        exact = not ((dt > 0) & (dt <= MIN_DT) & ~missing).any()
        if exact:
            start, advance = frame_rules(missing, dt, max_gap)
        else:
            start, advance = np.zeros_like(missing), np.zeros_like(missing)
            prev = np.full(len(t), np.nan)  # (S,) s, time of the last accepted frame
            for n in range(t.shape[1]):
                dt[:, n] = t[:, n] - prev
                start[:, n], advance[:, n] = frame_rules(missing[:, n], dt[:, n], max_gap)
                prev = np.where(start[:, n] | advance[:, n], t[:, n], prev)
    return start, advance, np.where(advance, dt, np.nan)


class Stepper(ABC):
    """The step contract every cleaner class follows: ``reset``, ``step``, ``clean``.

    (``faceclean.Cleaner`` is the public facade that wraps one of these.)
    """

    name: ClassVar[str] = "cleaner"
    offline: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs: object) -> None:
        super().__init_subclass__(**kwargs)
        own = cls.__dict__.get("clean")
        if own is not None and not getattr(own, "_finite_checked", False):
            cls.clean = _checked(own)  # a subclass's own clean gets the same check

    @property
    def stepwise(self) -> bool:
        """Whether ``clean`` is the base's reset-then-step (or a class's own, marked
        ``reset_then_step``, that a test proves equal to it): stepping the frames one by
        one gives its numbers, so a file may go through in blocks (io/stream.py)."""
        own = type(self).clean
        return not self.offline and (
            own in (Stepper.clean, StreamCleaner.clean) or getattr(own, "reset_then_step", False)
        )

    @abstractmethod
    def reset(self) -> None: ...

    @abstractmethod
    def step(self, frame: np.ndarray, t: float | np.ndarray) -> np.ndarray: ...

    def steps(self, times: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Step each frame of values (B, M) at times (B,) s in order, from the state the
        earlier steps left: (B, M), what ``step`` gives frame by frame (a class with a
        faster loop gives the same numbers). For a file that goes through in blocks
        (io/stream.py); the caller resets first and passes valid frames only."""
        out = np.empty((len(values), values.shape[1]))
        for k in range(len(values)):
            out[k] = self.step(values[k], times[k])
        return out

    def clean(self, anim: Animation) -> Animation:
        """Clean a whole clip: reset, then step every valid frame; missing frames stay NaN."""
        self.reset()
        out = np.full_like(anim.values, np.nan)
        valid = anim.valid
        for i in np.flatnonzero(valid):
            out[i] = self.step(anim.values[i], anim.times[i])
        check_finite(anim.values, out, self.name)
        return anim.with_values(out)

    clean._finite_checked = True  # type: ignore[attr-defined]


def check_finite(inp: np.ndarray, out: np.ndarray, name: str) -> None:
    """FacecleanError when ``out`` is not finite in a cell where ``inp`` (same shape) is
    finite and within MAX_ABS: a cleaner that erases data must not write a file."""
    lost = kept = 0
    for a in range(0, max(len(inp), 1), BLOCK):  # in blocks: no temporary as large as a take
        n_lost, n_kept = finite_counts(sane_cells(inp[a : a + BLOCK]), out[a : a + BLOCK])
        lost, kept = lost + n_lost, kept + n_kept
    refuse_lost(lost, kept, name)


def sane_cells(x: np.ndarray) -> np.ndarray:
    """Cells finite and within +-MAX_ABS (rule 2's good values), bool like x."""
    with np.errstate(invalid="ignore"):
        return np.abs(x) <= MAX_ABS  # (NaN compares False)


def finite_counts(sane: np.ndarray, out: np.ndarray) -> tuple[int, int]:
    """``check_finite``'s counts for one block: (cells lost, cells sane), from the input's
    ``sane_cells`` and the output."""
    return int(np.count_nonzero(sane & ~np.isfinite(out))), int(np.count_nonzero(sane))


def refuse_lost(lost: int, kept: int, name: str) -> None:
    """``check_finite``'s refusal, from its counts over a whole take."""
    if lost:
        raise FacecleanError(
            f"{name}: the output is not finite in {lost} of {kept} cells where the input "
            "is finite; check its parameters or model (nothing written)"
        )


def _checked(clean: Callable[[Stepper, Animation], Animation]) -> Callable:
    @functools.wraps(clean)
    def wrapper(self: Stepper, anim: Animation) -> Animation:
        out = clean(self, anim)
        check_finite(anim.values, out.values, self.name)
        return out

    wrapper._finite_checked = True  # type: ignore[attr-defined]
    return wrapper


class StreamCleaner(Stepper):
    """A causal cleaner with (S, M) state arrays. Subclasses give ``_start`` and ``_advance``.

    Parameters are fixed at construction (a new object changes them); ``__init__`` of a
    subclass sets its parameters and ends in ``reset()``.
    """

    max_gap: float = MAX_GAP  # s; longer pauses restart the state (rule 3)

    def reset(self) -> None:
        self._t: np.ndarray | None = None  # (S,) s, time of the last accepted frame
        self._y: np.ndarray | None = None  # (S, M) last output
        self._state: State | None = None

    @abstractmethod
    def _start(self, x: np.ndarray) -> State:
        """State that reproduces ``x`` (S, M) as the current output."""

    @abstractmethod
    def _advance(self, state: State, x: np.ndarray, dt: np.ndarray) -> tuple[State, np.ndarray]:
        """Advance by dt (S, 1) s > 0 with input x (S, M): (new state, output (S, M))."""

    def _compiled(self) -> Callable | None:
        """A compiled run of usual frames (filters/compiled.py), or None: step them."""
        return None

    def compiles(self, frames: int) -> bool:
        """Whether ``clean`` of a take of ``frames`` valid frames sends its runs to the
        compiled loop (filters/compiled.py ``for_take``: numba loads for a long take)."""
        from faceclean.filters import compiled

        return compiled.for_take(frames) and self._compiled() is not None

    def clean(self, anim: Animation, progress: Callable[[int], object] | None = None) -> Animation:
        """Reset, then step every valid frame (``Stepper.clean``). A usual frame (every
        value good, more than MIN_DT and at most max_gap after the last accepted one) goes
        to ``_advance`` at once, as ``step`` sends it, without step's conversions and
        checks of its arguments: the same numbers, some 15 us a frame less; a run of them,
        to the compiled loop where one is enabled (``_compiled``; a long take enables it,
        filters/compiled.py ``for_take``). The take goes through in blocks of BLOCK
        frames, so nothing but the output is as large as the input. ``progress`` (a
        progress bar's ``update``) is told, every PROGRESS_EVERY frames or more, how many
        more are done."""
        if type(self).step is not StreamCleaner.step:  # a subclass's own step decides
            return Stepper.clean(self, anim)
        from faceclean.filters import compiled

        self.reset()
        valid = anim.valid
        idx = np.flatnonzero(valid)
        out = np.empty_like(anim.values)  # every valid row is written below
        out[~valid] = np.nan
        t64 = anim.times[idx].astype(np.float64)  # (V,) s
        run = self._compiled() if compiled.for_take(len(idx)) else None
        told = lost = kept = 0
        for a in range(0, len(idx), BLOCK):
            rows = idx[a : a + BLOCK]
            first = int(rows[0])
            if rows[-1] - first == len(rows) - 1:  # no missing frame inside: views
                x, dst = anim.values[first : first + len(rows)], out[first : first + len(rows)]
            else:
                x, dst = anim.values[rows], np.empty((len(rows), out.shape[1]))
            sane = sane_cells(x)  # (B, M)
            self._block(np.ascontiguousarray(x), t64[a : a + BLOCK], dst, run, sane.all(axis=1))
            if dst.base is not out:
                out[rows] = dst
            n_lost, n_kept = finite_counts(sane, dst)  # check_finite, block by block
            lost, kept = lost + n_lost, kept + n_kept
            if progress is not None and a + len(rows) - told >= PROGRESS_EVERY:
                progress(a + len(rows) - told)
                told = a + len(rows)
        if progress is not None and len(idx) > told:
            progress(len(idx) - told)
        refuse_lost(lost, kept, self.name)
        return anim.with_values(out)

    def steps(self, times: np.ndarray, values: np.ndarray) -> np.ndarray:
        """``Stepper.steps`` through ``clean``'s block loop: usual frames straight to
        ``_advance``, runs of them to the compiled loop once a long take turned it on
        (filters/compiled.py ``for_take``): the same numbers as stepping."""
        if type(self).step is not StreamCleaner.step:  # a subclass's own step decides
            return Stepper.steps(self, times, values)
        from faceclean.filters import compiled

        run = self._compiled() if compiled.enabled() else None
        out = np.empty((len(values), values.shape[1]))
        for a in range(0, len(values), BLOCK):
            x = np.ascontiguousarray(values[a : a + BLOCK], dtype=np.float64)
            t64 = np.asarray(times[a : a + BLOCK], dtype=np.float64)
            self._block(x, t64, out[a : a + len(x)], run, sane_cells(x).all(axis=1))
        return out

    def _block(self, x: np.ndarray, t64: np.ndarray, dst: np.ndarray, run, ok) -> None:
        """``clean`` over one block: x (B, M) the valid frames at t64 (B,) s (read only:
        a view of the take), written to ``dst`` (B, M); ``run`` the compiled run, or None;
        ok (B,): every value of the frame sane."""
        # frame by frame, Python's own bool and float are faster; with runs, few are read
        good, times = (ok, t64) if run is not None else (ok.tolist(), t64.tolist())
        if run is not None:  # frame k + 1 chains on an accepted frame k: a usual frame
            d = np.diff(t64)
            chain = np.concatenate([[False], ok[1:] & (d > MIN_DT) & (d <= self.max_gap)])
            breaks = np.append(np.flatnonzero(~chain), len(x))  # runs end before these
        k, n = 0, len(x)
        while k < n:
            if good[k] and self._state is not None:
                dt = times[k] - float(self._t[0])
                if run is not None and MIN_DT < dt <= self.max_gap:
                    end = int(breaks[np.searchsorted(breaks, k, side="right")])
                    dts = np.empty(end - k)  # (end - k,) s
                    dts[0] = dt  # from the last accepted frame
                    dts[1:] = np.diff(t64[k:end])
                    self._state = run(self._state, x[k:end], dts, dst[k:end])
                    self._t[0], self._y = times[end - 1], dst[end - 1 : end].copy()
                    k = end
                    continue
                if MIN_DT < dt <= self.max_gap:  # (NaN fails)
                    xk = x[k : k + 1].copy()  # _advance's own: it may write in it
                    self._state, y = self._advance(self._state, xk, np.full((1, 1), dt))
                    self._t[0], self._y = times[k], y
                    dst[k] = y[0]
                    k += 1
                    continue
            dst[k] = self.step(x[k], times[k])
            k += 1

    clean._finite_checked = True  # type: ignore[attr-defined]

    def step(self, frame: np.ndarray, t: float | np.ndarray) -> np.ndarray:
        x = np.array(frame, dtype=np.float64, ndmin=1)
        single = x.ndim == 1
        x = x.reshape(1, -1) if single else x
        s = x.shape[0]
        t = np.broadcast_to(np.asarray(t, dtype=np.float64), (s,))
        if self._y is None:
            self._y = np.full_like(x, np.nan)
            self._t = np.full(s, np.nan)
        elif self._y.shape != x.shape:
            raise ValueError(f"frame shape {x.shape} != {self._y.shape} of earlier frames")
        elif self._state is not None and np.abs(x).max() <= MAX_ABS:  # (NaN fails it)
            # the usual frame: every value good, every stream advancing (rules 4-5), so
            # rules 1-3 do nothing; fewer numpy calls, the same numbers as below
            dt = t - self._t
            lo, hi = (dt[0], dt[0]) if s == 1 else (dt.min(), dt.max())
            if lo > MIN_DT and hi <= self.max_gap:  # (NaN, a stream not started, fails)
                self._state, y = self._advance(self._state, x, dt[:, None])
                self._t, self._y = t.copy(), y
                return y[0].copy() if single else y.copy()

        bad = ~(np.abs(x) <= MAX_ABS)  # non-finite or absurd (NaN compares False)
        missing = bad.all(axis=1) | ~np.isfinite(t)  # rule 1
        if bad.any():  # rule 2
            x = np.where(bad, np.nan_to_num(self._y, nan=0.0), x)
        dt = t - self._t  # NaN for streams not started
        start, advance = frame_rules(missing, dt, self.max_gap)

        if advance.all():
            self._state, y = self._advance(self._state, x, dt[:, None])
        else:
            y = self._y.copy()
            if advance.any():
                safe = np.where(advance, dt, 1.0)[:, None]
                new, y_adv = self._advance(self._state, x, safe)
                self._state = _merge(advance, new, self._state)
                y = np.where(advance[:, None], y_adv, y)
            if start.any():
                fresh = self._start(x)
                old = self._state if self._state is not None else fresh
                self._state = _merge(start, fresh, old)
                y = np.where(start[:, None], x, y)
        moved = start | advance
        self._t = np.where(moved, t, self._t)
        self._y = y
        return y[0].copy() if single else y.copy()


def _merge(rows: np.ndarray, new: State, old: State) -> State:
    """Per stream: ``new`` where rows (S,) is True, else ``old`` (state arrays (S, ...))."""
    return tuple(np.where(rows.reshape(-1, *[1] * (a.ndim - 1)), a, b)
                 for a, b in zip(new, old, strict=True))  # fmt: skip


class OfflineCleaner(Stepper):
    """A non-causal cleaner: only ``clean`` works; ``step`` refuses.

    The stream rules carry over: missing frames stay NaN; a non-finite or absurd value
    (rule 2) takes its channel's previous good value (0 before the first); a frame whose
    time is not after every earlier one (rule 4) repeats the previous output; ``_smooth``
    sees the rest, at strictly increasing times.
    """

    offline = True

    def reset(self) -> None:
        pass

    def step(self, frame: np.ndarray, t: float | np.ndarray) -> np.ndarray:
        raise TypeError(f"{self.name} is offline (non-causal): use clean(animation)")

    @abstractmethod
    def _smooth(self, times: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Smooth (N, M) values at (N,) increasing times; both without missing frames."""

    def clean(self, anim: Animation) -> Animation:
        out = np.full_like(anim.values, np.nan)
        rows = np.flatnonzero(anim.valid & np.isfinite(anim.times))  # (V,) rule 1
        if not len(rows):
            return anim.with_values(out)
        x = anim.values[rows]  # (V, M)
        bad = ~(np.abs(x) <= MAX_ABS)
        if bad.any():  # rule 2: each channel's previous good value (0 before the first)
            last = np.maximum.accumulate(np.where(bad, -1, np.arange(len(x))[:, None]), axis=0)
            good = x[np.maximum(last, 0), np.arange(x.shape[1])]
            x = np.where(last >= 0, good, 0.0)
        t = anim.times[rows]
        ahead = t > np.maximum.accumulate(np.concatenate(([-np.inf], t[:-1])))  # rule 4
        y = self._smooth(t[ahead], x[ahead])  # (A, M)
        held = np.cumsum(ahead) - 1  # (V,) index into y of the last frame ahead
        out[rows] = y[held]
        return anim.with_values(out)
