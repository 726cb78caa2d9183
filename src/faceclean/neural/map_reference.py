"""The benchmark's reference for the tracker map: its step naively in eager PyTorch.

``learned/tracker_map.py``'s step (docstring there) as a straightforward port would run
it, once per frame, ``torch.no_grad()``, float64 as the runtime: the model's inputs
gathered from the frame's columns, One Euro, the rest level, the linear map (and the
hidden layer, if any), the detail, the lift, the deadband, the outputs scattered into a
copy of the frame. It reads the settings of a built ``TrackerMap`` (the same weights, the
same pre-filter and detail), so it computes the same function (a test checks it); it
skips the time rules (every frame advances), which only favours it. Same
``start``/``step(x, dt)`` interface as ``neural.reference``.
"""

from __future__ import annotations

import numpy as np
import torch

from faceclean.channel_map import ChannelMap
from faceclean.filters.one_euro import DT_MIN
from faceclean.learned.band import CAP as BAND_CAP
from faceclean.learned.band import TAU as BAND_TAU


class MapReference:
    """``start(x (S, C))``, then ``step(x (S, C), dt (S,)) -> (S, C)`` numpy in and out,
    C the columns of the cleaner's ``names``."""

    def __init__(self, cleaner) -> None:
        w = cleaner.weights
        self.name = "reference tracker map (eager torch)"
        t64 = lambda a: torch.from_numpy(np.array(a, np.float64))  # noqa: E731
        a = {k: t64(v) for k, v in w.arrays.items()}
        inp, out = ChannelMap(w.inputs, cleaner.names), ChannelMap(w.outputs, cleaner.names)
        self.K, self.M = len(w.inputs), len(w.outputs)
        self.in_have, self.in_cols = torch.from_numpy(inp.have), torch.from_numpy(inp.cols)
        self.out_have, self.out_cols = torch.from_numpy(out.have), torch.from_numpy(out.cols)
        # the pre-filter's settings as the cleaner checked them (Hz, (K,))
        pre = cleaner.pre
        self.prefilter = cleaner.prefilter
        self.min_cutoff, self.beta, self.d_cutoff = (
            t64(np.broadcast_to(v, (self.K,))) for v in (pre.min_cutoff, pre.beta, pre.d_cutoff)
        )
        self.A, self.c = a["a"], a["c"]
        self.B = a["b"] if cleaner.rest else torch.zeros_like(a["b"])
        self.hidden = int(w.config["hidden"]) > 0
        self.mu, self.sd, self.w1, self.b1, self.w2, self.b2 = (
            a[k] for k in ("mu", "sd", "w1", "b1", "w2", "b2")
        )
        # the detail's gains as they run: the fitted ones times the scale (per output)
        scale = np.full(self.M, float(w.config.get("detail_scale", 1.0)))
        scale[out.have] = np.broadcast_to(cleaner.detail, (len(cleaner.names),))[out.cols]
        d = w.arrays["detail"] * scale
        self.do = torch.from_numpy(np.flatnonzero(d))  # (N,) outputs with a detail
        self.di = torch.tensor([w.inputs.index(w.outputs[j]) for j in self.do.tolist()])
        self.gain_d = t64(d)[self.do]
        lo = np.flatnonzero(w.arrays["lift_gain"] > 0)  # (L,) lifted outputs
        self.lo = torch.from_numpy(lo)
        li = [w.inputs.index(w.outputs[j]) for j in lo.tolist()]
        self.li = torch.tensor(li, dtype=torch.long)
        self.gain, self.knee = a["lift_gain"][self.lo], a["lift_knee"][self.lo]
        self.topped = bool(w.config.get("lift_top", False)) and len(lo) > 0
        self.lift_tau = w.lift_tau  # s, the lift's low-pass of its raw input
        band = np.broadcast_to(np.asarray(w.config.get("deadband", 0.0), np.float64), (self.M,))
        self.band = t64(band)
        self.noise_c = float(w.config.get("noise_band", 0.0))  # learned/band.py
        # (K,) each, per input: the rest's smoothing s, warm-up s, drift weight/s
        self.rest_tau, self.rest_warm, self.rest_drift = (t64(v.copy()) for v in w.rest)
        self.state: tuple | None = None

    @property
    def state_bytes(self) -> int:
        """Per stream: u, its slope, the rest level (K each), the map's output (M), the
        lift's top and low-pass (L each), with a noise band its last map value, step and
        noise (M each), float64."""
        rest = (self.K if self.rest_tau.any() else 0) + (1 if self.rest_warm.any() else 0)
        lifts = 2 * len(self.lo)
        return 8 * (3 * self.K + self.M + lifts + (3 * self.M if self.noise_c else 0) + rest)

    def _inputs(self, x: torch.Tensor) -> torch.Tensor:
        """(S, C) frame -> (S, K) model inputs (0 where the frame lacks one)."""
        xi = torch.zeros(x.shape[0], self.K, dtype=torch.float64)
        xi[:, self.in_have] = x[:, self.in_cols]
        return xi

    def _map(self, u, r, xi, top, p):
        """(S, K) u, r, xi, (S, L) the lift's low-pass p -> ((S, M) the map's output before
        the deadband, the top)."""
        out = u @ self.A.T + (u - r) @ self.B.T + self.c
        if len(self.do):  # d (x - u) on each output's own input
            out[:, self.do] += self.gain_d * (xi[:, self.di] - u[:, self.di])
        if self.hidden:
            z = (torch.cat([u, u - r], 1) - self.mu) / self.sd
            out = out + torch.tanh(z @ self.w1.T + self.b1) @ self.w2.T + self.b2
        out = out.clamp(0.0, 1.0)
        if len(self.lo):  # m_j = max(m_j, clip(l / max(1, top), 0, 1)), l = g (p - r - k)
            lift = self.gain * (p - r[:, self.li] - self.knee)
            if self.topped:
                top = torch.maximum(top, lift)
                lift = lift / top.clamp(min=1.0)
            out[:, self.lo] = torch.maximum(out[:, self.lo], lift.clamp(0.0, 1.0))
        return out, top

    @torch.no_grad()
    def start(self, x: np.ndarray) -> None:
        """First frames (S, C): u = r = the inputs, zero slope, the map's output."""
        xt = torch.from_numpy(np.asarray(x, np.float64))
        u = self._inputs(xt)
        top = torch.full((len(xt), len(self.lo)), -np.inf, dtype=torch.float64)
        p = u[:, self.li].clone()  # the lift's low-pass starts from the frame
        m, top = self._map(u, u.clone(), u, top, p)
        self.state = (u, torch.zeros_like(u), u.clone(), m, top, p)
        self.noise = (m.clone(), m.clone(), torch.zeros_like(m))  # m_{n-1}, m_{n-2}, s
        self.v, self.age = u.clone(), torch.zeros(len(xt), 1, dtype=torch.float64)  # the rest's

    @torch.no_grad()
    def step(self, x: np.ndarray, dt: np.ndarray) -> np.ndarray:
        """Advance by dt (S,) s with frames x (S, C)."""
        u, edx, r, prev, top, p = self.state
        xt = torch.from_numpy(np.asarray(x, np.float64))
        h = torch.from_numpy(np.asarray(dt, np.float64)).reshape(-1, 1).clamp(min=DT_MIN)
        xi = self._inputs(xt)
        if self.prefilter:  # One Euro: a(f) = 1 / (1 + 1 / (2 pi f h))
            ad = 1.0 / (1.0 + 1.0 / (2 * np.pi * self.d_cutoff * h))
            edx = edx + ad * ((xi - u) / h - edx)
            fc = self.min_cutoff + self.beta * edx.abs()
            u = u + (1.0 / (1.0 + 1.0 / (2 * np.pi * fc * h))) * (xi - u)
        else:
            u = xi
        v = u  # the rest: min(r + rho h, v), v = u smoothed over rest_tau s; u in rest_warm s
        if self.rest_tau.any():  # tau 0: v = u
            rate = torch.where(self.rest_tau > 0, 1.0 / self.rest_tau, torch.inf)
            v = self.v + -torch.expm1(-h * rate) * (u - self.v)
            v = torch.where(self.rest_tau > 0, v, u)
            self.v = v
        self.age = self.age + torch.from_numpy(np.asarray(dt, np.float64)).reshape(-1, 1)  # s
        r = torch.minimum(r + self.rest_drift * h, v)
        if self.rest_warm.any():  # r = v = u in the warm-up
            r = torch.where(self.age <= self.rest_warm, u, r)
            self.v = torch.where(self.age <= self.rest_warm, u, self.v)
        p = p + h / (h + self.lift_tau) * (xi[:, self.li] - p)  # the lift's low-pass
        m, top = self._map(u, r, xi, top, p)
        band = self.band
        if self.noise_c > 0:  # widened by the noise: c s, s the mean reversal
            p1, p2, s = self.noise
            d, d0 = m - p1, p1 - p2
            v = torch.where(d * d0 < 0, torch.minimum(d.abs(), d0.abs()), torch.zeros_like(d))
            s = s + h / (h + BAND_TAU) * (v - s)
            self.noise = (m.clone(), p1, s)
            band = torch.maximum(band, self.noise_c * s).clamp(max=BAND_CAP)
        m = m - (m - prev).clamp(-band, band)  # the deadband
        self.state = (u, edx, r, m, top, p)
        y = xt.clone()
        y[:, self.out_cols] = m[:, self.out_have]
        return y.numpy()
