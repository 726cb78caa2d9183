"""Training loss of the recurrent cleaner (SPEC section 2, plus a smoothness term).

    L = L_MSE + w_der L_der + w_dis L_dis + w_acc L_acc

- L_MSE = mean (x_gt - x̂)^2 over valid frames and channels;
- L_der = sum_k mean (x_gt^(k) - x̂^(k))^2, forward derivatives (Eq. 1), 1/s^k;
- L_dis = mean |D_gt - D̂| + α_dis |D_i - D̂| over the 6 lip/eyelid distances of a face
  mesh deformed by the weights (faceclean.face.vertex_pairs; distances in mouth widths);
- L_acc (ours) = mean (x_gt'' - x̂'')^2, second time-derivatives on the real,
  irregular times, 1/s^2: the paper's terms reward amplitude and leave most jitter in.

Frames where the tracker lost the face or the truth is unknown (``valid`` False) count in
no term, nor do derivatives that span them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from faceclean.channel_map import ChannelMap
from faceclean.channels import ARKIT52
from faceclean.face.vertex_pairs import LossFace


@dataclass(frozen=True)
class Weights:
    """Loss weights; the paper's are w_der 0.01, w_dis 0.1, α_dis 0.8 and no L_acc."""

    der: float = 0.01
    dis: float = 0.1
    alpha_dis: float = 0.8
    acc: float = 1e-6  # s^4: ~1 for 60 fps jitter of 0.01 (x'' ~ 1e3 /s^2)


class Loss:
    """Callable loss for a model's channels; the mesh's pair vertices are precomputed."""

    def __init__(
        self, channels: Sequence[str], face: LossFace | None, weights: Weights = Weights()
    ):
        self.w = weights
        self.mesh: tuple[Tensor, Tensor, float] | None = None
        if face is not None and weights.dis > 0:
            idx = ChannelMap(channels, ARKIT52).src
            dv = np.zeros((len(channels), 6, 2, 3))  # (M, 6, 2, 3) mesh units per weight
            for m, j in enumerate(idx):
                if j >= 0:
                    dv[m] = face.mesh.deltas[j][face.pairs]
            v0 = torch.tensor(face.mesh.vertices[face.pairs], dtype=torch.float32)  # (6, 2, 3)
            self.mesh = (v0, torch.tensor(dv, dtype=torch.float32), face.scale)

    def distances(self, x: Tensor) -> Tensor:
        """(B, T, 6) pair distances in mouth widths for weights x (B, T, M)."""
        v0, dv, scale = self.mesh
        p = v0 + torch.einsum("btm,mpvc->btpvc", x, dv)  # (B, T, 6, 2, 3)
        return (p[..., 0, :] - p[..., 1, :]).norm(dim=-1) / scale

    def __call__(
        self,
        y: Tensor,
        d: Tensor,
        stepped: Tensor,
        noisy: Tensor,
        truth: Tensor,
        t: Tensor,
        valid: Tensor,
    ) -> tuple[Tensor, dict[str, float]]:
        """(total, parts) for outputs y (B, T, M), predicted derivatives d (B, T-1, K*M)
        with ``stepped`` (B, T-1), inputs ``noisy`` and targets ``truth`` (B, T, M),
        times t (B, T) s and ``valid`` (B, T) bool."""
        M = y.shape[-1]
        K = d.shape[-1] // M
        v = valid.float()
        parts: dict[str, Tensor] = {"mse": _masked((truth - y) ** 2, v)}

        # L_der: x_gt^(k)[n] by forward differences, against the step's x̂^(k)[n]
        dt = (t[:, 1:] - t[:, :-1]).clamp_min(1e-6).unsqueeze(-1)  # (B, T-1, 1) s
        ok = v[:, 1:] * v[:, :-1] * stepped.float()  # (B, T-1)
        g, der, mask = truth, y.new_zeros(()), ok
        for k in range(K):
            g = (g[:, 1:] - g[:, :-1]) / dt[:, : g.shape[1] - 1]  # (B, T-1-k, M)
            n = g.shape[1]
            mask = mask[:, :n] * ok[:, k : k + n]  # frames n..n+k+1 all valid
            der = der + _masked((g - d[:, :n, k * M : (k + 1) * M]) ** 2, mask)
        parts["der"] = der

        # L_acc: three-point second derivative on the irregular grid
        acc_mask = v[:, 2:] * v[:, 1:-1] * v[:, :-2]
        parts["acc"] = _masked((_second(t, truth) - _second(t, y)) ** 2, acc_mask)

        if self.mesh is not None:
            dy, dg, di = (self.distances(a) for a in (y, truth, noisy))
            parts["dis"] = _masked((dg - dy).abs() + self.w.alpha_dis * (di - dy).abs(), v)
        else:
            parts["dis"] = y.new_zeros(())
        total = (
            parts["mse"]
            + self.w.der * parts["der"]
            + self.w.dis * parts["dis"]
            + self.w.acc * parts["acc"]
        )
        return total, {k: float(p.detach()) for k, p in parts.items()}


def _second(t: Tensor, x: Tensor) -> Tensor:
    """(B, T-2, M) x'' = 2 (s1 - s0) / (h0 + h1) with slopes s over real intervals h."""
    h = (t[:, 1:] - t[:, :-1]).clamp_min(1e-6).unsqueeze(-1)  # (B, T-1, 1) s
    s = (x[:, 1:] - x[:, :-1]) / h  # (B, T-1, M) 1/s
    return 2.0 * (s[:, 1:] - s[:, :-1]) / (h[:, 1:] + h[:, :-1])


def _masked(err: Tensor, mask: Tensor) -> Tensor:
    """Mean of err (B, N, C) over the rows where mask (B, N) is 1."""
    w = mask.unsqueeze(-1).expand_as(err) > 0
    return torch.where(w, err, torch.zeros_like(err)).sum() / w.sum().clamp_min(1)
