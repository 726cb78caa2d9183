"""The paper's causal recurrent cleaner (Berson et al. 2020, SPEC section 2).

One step runs when input frame n+1 arrives, with dt = t[n+1] - t[n] seconds:

    x_c^(k)[n]  = (x_i^(k-1)[n+1] - x̂^(k-1)[n]) / dt            Eq. 2, k = 1..K
    features    = [x̂[n], x̂^(1..K)[n-1], x_c^(1..K)[n]]           (B, F), F = M (1 + 2K)
    h           = LSTM layers((features - feat_mean) / feat_std)  residual for l > 0
    x̂^(k)[n]    = x_c^(k)[n] + out_scale · dense(h)              output residual
                  (1 + tanh(a)) · x_c^(k)[n] + out_scale · b      output="gated", (a, b) = dense(h)
                  (1 - exp(-dt / (2 ms e^a))) · x_c^(k)[n] + out_scale · b  output="rate"
    x̂^(k-1)[n+1] = x̂^(k-1)[n] + dt x̂^(k)[n]                     k = K..1, x̂ clamped

For K >= 2 the input's derivatives are causal backward differences,
x_i^(j)[n+1] = (x_i^(j-1)[n+1] - x_i^(j-1)[n]) / dt, and the estimate's intermediate
derivatives x̂^(j)[n] (1 <= j < K) in Eq. 2 are integrated from the previous step's
predictions: x̂^(j)[n] = x̂^(j)[n-1] + dt[n-1] x̂^(j+1)[n-1].
A zero network follows the input exactly (x̂[n+1] = x_i[n+1]); it learns corrections.
The gated head (ours) also learns a per-channel, per-frame gain on x_c: for K = 1,
x̂[n+1] = x̂[n] + g (x_i[n+1] - x̂[n]) + dt out_scale b with g = 1 + tanh(a), an adaptive
low-pass where g < 1; a zero network still gives g = 1, b = 0 (follows the input).
That gain is per frame while the network does not see dt, so one output means another
cutoff at every frame rate; the "rate" head instead outputs a time constant
tau = RATE_TAU0 e^a and uses the one-pole gain g = 1 - exp(-dt / tau), the same filter
in seconds at any rate (a zero network is a 2 ms low-pass: g = 0.98 at 120 fps).

``forward`` applies the runtime's time rules (filters/base.py) inside a batch: a missing
frame (all NaN or t NaN) holds the output and the state, a NaN channel takes the last
output, and a pause longer than ``MAX_GAP`` seconds restarts from the input; which frames
advance or restart is decided by filters/base.py's ``time_rules``, not coded here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor, nn

from faceclean.filters.base import MAX_GAP, time_rules
from faceclean.learned.checkpoint import RATE_A_MAX, RATE_TAU0

OUTPUTS = ("additive", "gated", "rate")  # the paper's residual, or gain + residual


class State(NamedTuple):
    """Recurrent state of B streams."""

    y: Tensor  # (B, M) last output x̂[n]
    d: Tensor  # (B, K*M) last predicted derivatives x̂^(1..K)[n-1], 1/s^k
    z: Tensor  # (B, (K-1)*M) integrated estimate derivatives x̂^(1..K-1)[n], 1/s^k
    xi: Tensor  # (B, (K-1)*M) input and its backward derivatives x_i^(0..K-2)[n]
    h: tuple[Tensor, ...]  # L x (B, H)
    c: tuple[Tensor, ...]  # L x (B, H)


class LSTMCleaner(nn.Module):
    """Stacked-LSTM corrector of K time-derivatives, closed loop, any frame rate.

    Parameters map 1:1 to the checkpoint keys of docs/ARCHITECTURE.md:
    ``lstm.{l}`` (nn.LSTMCell, gates i, f, g, o) and ``head`` (nn.Linear).
    """

    def __init__(
        self,
        channels: Sequence[str],
        K: int = 1,
        hidden: int = 128,
        layers: int = 2,
        dropout: float = 0.3,
        value_range: tuple[float, float] = (0.0, 1.0),
        output: str = "additive",
    ) -> None:
        super().__init__()
        if K < 1 or layers < 1 or hidden < 1 or not channels:
            raise ValueError("need K >= 1, layers >= 1, hidden >= 1 and some channels")
        if output not in OUTPUTS:
            raise ValueError(f"output must be one of {', '.join(OUTPUTS)}, not {output!r}")
        self.output = output
        self.channels = tuple(channels)
        self.M = len(self.channels)
        self.K = int(K)
        self.hidden = int(hidden)
        self.layers = int(layers)
        self.dropout = float(dropout)
        self.value_range = (float(value_range[0]), float(value_range[1]))
        self.F = self.M * (1 + 2 * self.K)
        self.lstm = nn.ModuleList(
            nn.LSTMCell(self.F if i == 0 else hidden, hidden) for i in range(layers)
        )
        # additive: (K*M,) corrections; gated: (2*K*M,) = [a (gain logits), b (corrections)]
        self.head = nn.Linear(hidden, self.K * self.M * (1 if output == "additive" else 2))
        nn.init.zeros_(self.head.weight)  # start as the identity: follow the input
        nn.init.zeros_(self.head.bias)
        self.drop = nn.Dropout(self.dropout)
        self.register_buffer("feat_mean", torch.zeros(self.F))
        self.register_buffer("feat_std", torch.ones(self.F))
        self.register_buffer("out_scale", torch.ones(self.K * self.M))

    def config(self) -> dict:
        """The constructor arguments (the checkpoint's ``config`` minus training facts)."""
        return {
            "channels": list(self.channels),
            "K": self.K,
            "hidden": self.hidden,
            "layers": self.layers,
            "dropout": self.dropout,
            "value_range": list(self.value_range),
            "output": self.output,
        }

    def init_state(self, B: int, x0: Tensor | None = None) -> State:
        """State of B streams started at x̂[0] = x0 (B, M) (zeros when None)."""
        ref = self.feat_mean
        y = torch.zeros(B, self.M, dtype=ref.dtype, device=ref.device) if x0 is None else x0
        km = self.K * self.M
        zeros = y.new_zeros
        xi = torch.cat([y, zeros(B, (self.K - 2) * self.M)], 1) if self.K > 1 else zeros(B, 0)
        h = tuple(zeros(B, self.hidden) for _ in range(self.layers))
        c = tuple(zeros(B, self.hidden) for _ in range(self.layers))
        return State(y, zeros(B, km), zeros(B, km - self.M), xi, h, c)

    def features(self, state: State, x_new: Tensor, dt: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Raw features (B, F), corrective derivatives x_c (B, K*M), input derivs (B, K*M).

        x_new (B, M), dt (B,) seconds > 0.
        """
        dt = dt.reshape(-1, 1)
        M = self.M
        xin = [x_new]  # x_i^(j)[n+1], j = 0..K-1 (backward differences)
        for j in range(1, self.K):
            xin.append((xin[j - 1] - state.xi[:, (j - 1) * M : j * M]) / dt)
        est = [state.y] + [state.z[:, j * M : (j + 1) * M] for j in range(self.K - 1)]
        xc = torch.cat([(xin[k] - est[k]) / dt for k in range(self.K)], 1)  # Eq. 2
        return torch.cat([state.y, state.d, xc], 1), xc, torch.cat(xin, 1)

    def step(self, state: State, x_new: Tensor, dt: Tensor) -> tuple[State, Tensor]:
        """One causal step: input frame x_new (B, M) arrived dt (B,) s after the last one."""
        feats, xc, xin = self.features(state, x_new, dt)
        u = (feats - self.feat_mean) / self.feat_std
        hs, cs = [], []
        for i, cell in enumerate(self.lstm):
            h, c = cell(u, (state.h[i], state.c[i]))
            hs.append(h)
            cs.append(c)
            h = h + u if i > 0 else h  # residual where sizes match
            u = self.drop(h)
        if self.output == "gated":
            a, b = self.head(u).chunk(2, dim=1)  # (B, K*M) each
            d = (1.0 + torch.tanh(a)) * xc + self.out_scale * b  # (B, K*M) x̂^(1..K)[n]
        elif self.output == "rate":
            a, b = self.head(u).chunk(2, dim=1)  # (B, K*M) each; tau = TAU0 e^a s
            a = a.clamp(-RATE_A_MAX, RATE_A_MAX)
            rate = torch.exp(-a) * (dt.reshape(-1, 1) / RATE_TAU0)  # dt / tau
            d = (1.0 - torch.exp(-rate)) * xc + self.out_scale * b  # one-pole gain
        else:
            d = xc + self.out_scale * self.head(u)  # (B, K*M) x̂^(1..K)[n]
        dtc = dt.reshape(-1, 1)
        M = self.M
        y = (state.y + dtc * d[:, :M]).clamp(*self.value_range)
        # x̂^(j)[n+1] = x̂^(j)[n] + dt x̂^(j+1)[n], 1 <= j < K (Eq. 1 integrated)
        z = d[:, : (self.K - 1) * M] + dtc * d[:, M:]
        xi = xin[:, : (self.K - 1) * M]
        return State(y, d, z, xi, tuple(hs), tuple(cs)), y

    def forward(
        self, x: Tensor, t: Tensor, return_derivatives: bool = False
    ) -> Tensor | tuple[Tensor, Tensor, Tensor]:
        """Closed-loop unroll over (B, T, M) inputs at (B, T) times from x̂[0] = x[0].

        Returns y (B, T, M); with ``return_derivatives`` also d (B, T-1, K*M), the
        predicted x̂^(1..K)[n] made when frame n+1 arrived, and ``stepped`` (B, T-1)
        bool, where that step really advanced (held or restarted steps are False).
        Missing frames (NaN rows or NaN times) hold the last output.
        """
        B, T, M = x.shape
        bad = torch.isnan(x)
        x = torch.where(bad, torch.zeros_like(x), x)
        advance, start = _time_rules(bad.all(-1) | torch.isnan(t), t)
        dt_all = torch.from_numpy(advance.dt).to(t)  # (B, T) s since the last accepted frame
        everywhere = advance.mask.all(0)  # (T,) python-side: no per-step syncs
        adv_t = torch.from_numpy(advance.mask).to(x.device)
        start_t = torch.from_numpy(start).to(x.device)
        state = self.init_state(B, x[:, 0])
        ys, ds = [state.y], []
        for n in range(1, T):
            xn = torch.where(bad[:, n], state.y, x[:, n])  # NaN channel: last output
            new, y = self.step(state, xn, dt_all[:, n])
            if not everywhere[n]:
                fresh = self.init_state(B, xn)
                picked = (
                    _pick(adv_t[:, n], start_t[:, n], a, b, o)
                    for a, b, o in zip(new, fresh, state, strict=True)
                )
                state = State(*picked)
                y = state.y
            else:
                state = new
            ys.append(y)
            ds.append(new.d)
        stepped = adv_t[:, 1:]
        y = torch.stack(ys, 1)
        if not return_derivatives:
            return y
        if T < 2:
            return y, x.new_zeros(B, 0, self.K * M), torch.zeros(B, 0, dtype=torch.bool)
        return y, torch.stack(ds, 1), stepped


class _Advance(NamedTuple):
    mask: np.ndarray  # (B, T) bool: frame n advances the state by dt[:, n]
    dt: np.ndarray  # (B, T) s, 1.0 where not advancing (any positive value does)


def _time_rules(missing: Tensor, t: Tensor) -> tuple[_Advance, np.ndarray]:
    """The runtime's time rules (filters/base.py) over a batch: (advance, start (B, T))."""
    miss = missing.detach().cpu().numpy()
    start, adv, dt = time_rules(t.detach().cpu().double().numpy(), miss, MAX_GAP)
    return _Advance(adv, np.where(adv, dt, 1.0)), start


def _pick(advance: Tensor, start: Tensor, new, fresh, old):
    """Per stream: ``new`` where advanced, ``fresh`` where restarted, else ``old``."""
    if isinstance(new, tuple):
        return tuple(
            _pick(advance, start, a, b, o) for a, b, o in zip(new, fresh, old, strict=True)
        )
    a = advance.reshape(-1, 1)
    s = start.reshape(-1, 1)
    return torch.where(a, new, torch.where(s, fresh, old))
