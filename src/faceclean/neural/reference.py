"""The benchmark's reference: the paper's architecture stepped naively in eager PyTorch.

Two ``nn.LSTMCell(·, 128)`` layers (residual around the second), a ``nn.Linear`` head,
SPEC section 2's feature and integration arithmetic in plain tensor ops, one call per
frame, ``torch.no_grad()``, as a straightforward port would run it. It loads the same
checkpoint as the runtime, so it computes the same function (a test checks it), and
it skips the time rules (every frame advances), which only favours it.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from faceclean.learned.checkpoint import RATE_A_MAX, RATE_TAU0, LSTMWeights


def single_thread() -> str:
    """Run torch on one thread, as the reference is timed; returns torch's version."""
    torch.set_num_threads(1)
    return torch.__version__


class NaiveReference:
    """``reset()``, then ``step(x (S, M), dt (S,)) -> (S, M)`` numpy in and out."""

    name = "reference (eager torch)"

    def __init__(self, weights: LSTMWeights) -> None:
        H, M = weights.hidden, len(weights.channels)
        self.cells = [
            nn.LSTMCell(w.shape[1], H) for w in weights.w_ih
        ]  # layer l: input (F or H) -> H
        self.head = nn.Linear(H, weights.head_w.shape[0])  # M, or 2M for a gain head
        self.output = weights.output
        with torch.no_grad():
            for cell, w_ih, w_hh, b_ih, b_hh in zip(
                self.cells, weights.w_ih, weights.w_hh, weights.b_ih, weights.b_hh, strict=True
            ):
                cell.weight_ih.copy_(torch.from_numpy(w_ih))
                cell.weight_hh.copy_(torch.from_numpy(w_hh))
                cell.bias_ih.copy_(torch.from_numpy(b_ih))
                cell.bias_hh.copy_(torch.from_numpy(b_hh))
            self.head.weight.copy_(torch.from_numpy(weights.head_w))
            self.head.bias.copy_(torch.from_numpy(weights.head_b))
        self.mean = torch.from_numpy(weights.feat_mean)
        self.std = torch.from_numpy(weights.feat_std)
        self.out_scale = torch.from_numpy(weights.out_scale)
        self.lo, self.hi = weights.value_range
        self.M, self.H = M, H
        self.state: tuple | None = None

    @property
    def state_bytes(self) -> int:
        """Per stream: x̂, x̂', and h, c of every layer, float32."""
        return 4 * (2 * self.M + 2 * self.H * len(self.cells))

    def reset(self) -> None:
        self.state = None

    def start(self, x: np.ndarray) -> None:
        """First frames (S, M): x̂[0] = x, zero derivative and LSTM state."""
        y = torch.from_numpy(np.asarray(x, np.float32))
        S = y.shape[0]
        hc = [(torch.zeros(S, self.H), torch.zeros(S, self.H)) for _ in self.cells]
        self.state = (y, torch.zeros_like(y), hc)

    @torch.no_grad()
    def step(self, x: np.ndarray, dt: np.ndarray) -> np.ndarray:
        """Advance by dt (S,) seconds with frames x (S, M)."""
        y, d, hc = self.state
        xn = torch.from_numpy(np.asarray(x, np.float32))
        dtt = torch.from_numpy(np.asarray(dt, np.float32)).reshape(-1, 1)
        xc = (xn - y) / dtt  # Eq. 2
        u = (torch.cat([y, d, xc], 1) - self.mean) / self.std
        new = []
        for i, cell in enumerate(self.cells):
            h, c = cell(u, hc[i])
            new.append((h, c))
            u = h + u if i > 0 else h
        if self.output == "additive":
            d = xc + self.out_scale * self.head(u)
        else:  # gain logits a, then corrections b (docs/ARCHITECTURE.md)
            a, b = self.head(u).chunk(2, dim=1)
            if self.output == "gated":
                g = 1.0 + torch.tanh(a)
            else:  # "rate": one-pole gain of time constant RATE_TAU0 e^a
                g = 1.0 - torch.exp(-torch.exp(-a.clamp(-RATE_A_MAX, RATE_A_MAX)) * dtt / RATE_TAU0)
            d = g * xc + self.out_scale * b
        y = (y + dtt * d).clamp(self.lo, self.hi)
        self.state = (y, d, new)
        return y.numpy()
