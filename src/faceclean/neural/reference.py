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


class AdaptiveReference:
    """The adaptive model (learned/adaptive.py) stepped naively in eager PyTorch: the loop
    body of ``neural.adaptive.AdaptiveNet`` (its GRUCell and head, the features, the One
    Euro arithmetic) once per frame, ``torch.no_grad()``, the core always run, as a
    straightforward port would. Same ``start``/``step(x, dt)`` interface as above."""

    name = "reference adaptive (eager torch)"

    def __init__(self, weights) -> None:
        from faceclean.neural.adaptive import AdaptiveNet

        self.net = AdaptiveNet.from_weights(weights).eval()
        self.M, self.H = self.net.M, self.net.H
        self.state: tuple | None = None

    @property
    def state_bytes(self) -> int:
        """Per stream: y, edx, the slow level and the GRU state, float32."""
        return 4 * self.M * (3 + self.H)

    def start(self, x: np.ndarray) -> None:
        y = torch.from_numpy(np.asarray(x, np.float32))
        h = torch.zeros(y.shape[0] * self.M, self.H)
        self.state = (y, torch.zeros_like(y), h, y.clone())

    @torch.no_grad()
    def step(self, x: np.ndarray, dt: np.ndarray) -> np.ndarray:
        from faceclean.learned import adaptive as A
        from faceclean.neural.adaptive import alpha

        net, (y, edx, h, slow) = self.net, self.state
        S, M = y.shape
        xn = torch.from_numpy(np.asarray(x, np.float32))
        dtt = torch.from_numpy(np.asarray(dt, np.float32)).reshape(-1, 1).clamp_min(A.DT_MIN)
        e = xn - y
        edx = edx + alpha(net.d_cutoff, dtt) * (e / dtt - edx)
        en = e / A.E0
        f = torch.stack(
            [
                en,
                (edx / A.V0).clamp(-4.0, 4.0),
                en.abs(),
                en.abs() @ net.group.T,
                en.abs().mean(1, keepdim=True).expand(-1, M),
                en[:, net.mirror],
                torch.log(60.0 * dtt).expand(-1, M),
            ],
            -1,
        ).clamp(-A.F_MAX, A.F_MAX)
        f = torch.cat([f, net.emb.expand(S, M, -1)], -1).reshape(S * M, -1)
        h = net.cell(f, h)
        o = net.head(h).reshape(S, M, 2)
        mc, be = net.log_min_cutoff.exp(), net.log_beta.exp()
        fc = (mc + be * edx.abs()) * torch.exp(o[..., 0].clamp(A.A_MIN, A.A_MAX))
        p = y + torch.sigmoid(o[..., 1]) * dtt * edx
        y = p + alpha(fc, dtt) * (xn - p)
        lo, hi = xn.clamp(max=0.0), xn.clamp(min=1.0)
        y = torch.minimum(torch.maximum(y, lo), hi)
        slow = slow + alpha(torch.tensor(A.F_SLOW), dtt) * (y - slow)
        shown = y + A.G_MAX * torch.tanh(net.boost) * (y - slow)
        shown = torch.minimum(torch.maximum(shown, lo), hi)
        self.state = (y, edx, h, slow)
        return shown.numpy()


class DerivativeReference:
    """The paper's FC or GBT baseline (learned/derivative_net.py) stepped naively in eager
    PyTorch: backward-difference features, the model (the MLP as ``nn.Linear`` layers; the
    trees as one gather-and-compare per level over every tree), the complementary blend,
    once per frame. Same ``start``/``step(x, dt)`` interface as above. Float64 as the
    runtime (a tree's threshold compare must see the same numbers), the MLP's layers
    float32 as the runtime's."""

    def __init__(self, cleaner) -> None:
        from faceclean.learned.derivative_net import BoostedTrees, group_index

        self.K, self.alpha, self.lo, self.hi = cleaner.K, cleaner.alpha, cleaner.lo, cleaner.hi
        self.M = len(cleaner.channels)
        self.trees = isinstance(cleaner, BoostedTrees)
        self.name = f"reference {cleaner.name} (eager torch)"
        t64 = lambda a: torch.from_numpy(np.ascontiguousarray(a, np.float64))  # noqa: E731
        if self.trees:
            c = cleaner
            self.feat = torch.from_numpy(c._feat.ravel().astype(np.int64))
            self.thr, self.val = t64(c._thr.ravel()), t64(c._val.ravel())
            self.in_off = torch.from_numpy(c._in_off.astype(np.int64))
            self.leaf_off = torch.from_numpy(c._leaf_off.astype(np.int64))
            self.depth = c._depth
            self.onehot = t64(np.eye(self.K)[c._order])  # (T, K): tree -> its order
            self.base, self.ostd = t64(c._base), t64(c._ostd)
            self.groups = t64(group_index(c.channels))
        else:
            layers = []  # float32 layers (torch's default, the runtime's too)
            for i, (w, b) in enumerate(zip(cleaner._w, cleaner._b, strict=True)):
                lin = nn.Linear(w.shape[0], w.shape[1])  # the runtime keeps w as (in, out)
                with torch.no_grad():
                    lin.weight.copy_(torch.from_numpy(np.ascontiguousarray(w.T)))
                    lin.bias.copy_(torch.from_numpy(b))
                layers += [lin] + ([nn.ReLU()] if i < len(cleaner._w) - 1 else [])
            self.mlp = nn.Sequential(*layers)
            self.fm, self.fs = (t64(a) for a in cleaner._feat_scaling)
            self.om, self.os = t64(cleaner._om), t64(cleaner._os)
            self.clip = float(cleaner.config.get("feat_clip", np.inf))
        self.state: tuple | None = None

    @property
    def state_bytes(self) -> int:
        """Per stream: the input's K + 1 derivatives and the K blended ones, float64."""
        return 8 * self.M * (2 * self.K + 1)

    def start(self, x: np.ndarray) -> None:
        xt = torch.from_numpy(np.asarray(x, np.float64))
        zero = torch.zeros_like(xt)
        self.state = ([xt, *[zero] * self.K], [xt, *[zero] * (self.K - 1)])

    def _predict(self, feats):
        """(S, M, 1 + 2K) features -> (S, M, K) derivative predictions."""
        S, M, F = feats.shape
        if not self.trees:
            h = ((feats.transpose(1, 2).reshape(S, F * M) - self.fm) / self.fs).clamp(
                -self.clip, self.clip
            )
            out = self.mlp(h.float()).double() * self.os + self.om  # (S, K M) order-major
            return out.reshape(S, self.K, M).transpose(1, 2)
        x = torch.cat([feats, self.groups.expand(S, M)[..., None]], -1).reshape(S * M, -1)
        pos = torch.zeros(S * M, len(self.in_off), dtype=torch.int64)  # (n, T)
        for _ in range(self.depth):
            flat = pos + self.in_off
            right = torch.gather(x, 1, self.feat[flat]) > self.thr[flat]
            pos = 2 * pos + 1 + right
        leaf = self.val[pos + self.leaf_off]  # (n, T)
        return ((leaf @ self.onehot + self.base) * self.ostd).reshape(S, M, self.K)

    @torch.no_grad()
    def step(self, x: np.ndarray, dt: np.ndarray) -> np.ndarray:
        from faceclean.learned.derivative_net import ALPHA_RATE, BIG

        d_old, r_old = self.state
        dtt = torch.from_numpy(np.asarray(dt, np.float64)).reshape(-1, 1)
        d_new = [torch.from_numpy(np.asarray(x, np.float64))]
        for k in range(1, self.K + 1):  # backward differences ending at the new frame
            d_new.append(((d_new[k - 1] - d_old[k - 1]) / dtt).clamp(-BIG, BIG))
        pred = self._predict(torch.stack([*d_new, *d_old[1:]], -1))
        a = self.alpha ** (dtt * ALPHA_RATE)  # (S, 1)
        target = [d_new[0], *pred.unbind(-1)]
        r_new = [a * (r_old[k] + dtt * target[k + 1]) + (1 - a) * target[k] for k in range(self.K)]
        r_new[0] = r_new[0].clamp(self.lo, self.hi)
        self.state = (d_new, r_new)
        return r_new[0].numpy()
