"""The calibration clip a user records before a take: a neutral hold, then a range of motion.

``clip(rate) -> (times (N,) s, weights (N, 52))``: ``NEUTRAL_S`` s of neutral face, then
each of ``POSES`` in turn, every one eased in, held and eased out (``RAMP_S``, ``HOLD_S``,
``RAMP_S``), back to neutral between poses. A pose moves symmetric channels together, as a
person does when asked to "blink" or "smile", and drives each channel it names to its full
range (1.0), so that ``calibration.calibrate(..., rom=True)`` sees every channel's top.
tongueOut is left out (MediaPipe has no tongue score). The pairs engine renders it with the
same face, light and camera as the take it calibrates (``engine.Worker.run_rom``).
"""

from __future__ import annotations

import numpy as np

from faceclean.channels import ARKIT52

NEUTRAL_S = 1.0  # s, matches calibration.NEUTRAL_S (the hold calibrate reads)
RAMP_S = 0.15  # s, ease in (and out) of a pose
HOLD_S = 0.2  # s at full range

_LR = ("Left", "Right")
POSES: tuple[dict[str, float], ...] = (
    *({f"{c}{s}": 1.0 for s in _LR} for c in ("eyeBlink", "eyeWide", "eyeSquint")),
    *({f"{c}{s}": 1.0 for s in _LR} for c in ("eyeLookUp", "eyeLookDown")),
    {"eyeLookInLeft": 1.0, "eyeLookOutRight": 1.0},
    {"eyeLookOutLeft": 1.0, "eyeLookInRight": 1.0},
    {"browDownLeft": 1.0, "browDownRight": 1.0},
    {"browInnerUp": 1.0},
    {"browOuterUpLeft": 1.0, "browOuterUpRight": 1.0},
    *({c: 1.0} for c in ("jawOpen", "jawLeft", "jawRight", "jawForward")),
    {"jawOpen": 0.4, "mouthClose": 0.4},  # lips together with the jaw open: its full range
    *({c: 1.0} for c in ("mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight")),
    *(
        {f"{c}{s}": 1.0 for s in _LR}
        for c in ("mouthSmile", "mouthFrown", "mouthDimple", "mouthStretch", "mouthPress")
    ),
    {"mouthRollLower": 1.0, "mouthRollUpper": 1.0},
    {"mouthShrugLower": 1.0, "mouthShrugUpper": 1.0},
    {f"{c}{s}": 1.0 for c in ("mouthLowerDown", "mouthUpperUp") for s in _LR},
    {"cheekPuff": 1.0},
    {"cheekSquintLeft": 1.0, "cheekSquintRight": 1.0},
    {"noseSneerLeft": 1.0, "noseSneerRight": 1.0},
)


def seconds() -> float:
    """The clip's length in s."""
    return NEUTRAL_S + len(POSES) * (2 * RAMP_S + HOLD_S)


def clip(rate: float) -> tuple[np.ndarray, np.ndarray]:
    """(times (N,) s from 0 at ``rate`` Hz, ARKit-52 weights (N, 52) in [0, 1])."""
    t = np.arange(int(seconds() * rate) + 1) / rate
    w = np.zeros((len(t), len(ARKIT52)))
    col = {n: i for i, n in enumerate(ARKIT52)}
    span = 2 * RAMP_S + HOLD_S
    for k, pose in enumerate(POSES):
        u = t - (NEUTRAL_S + k * span)  # s into this pose
        # smoothstep ease: 0 -> 1 over RAMP_S, hold, 1 -> 0 over RAMP_S
        up = np.clip(u / RAMP_S, 0, 1)
        down = np.clip((span - u) / RAMP_S, 0, 1)
        env = np.minimum(up, down)
        env = env * env * (3 - 2 * env)
        for name, peak in pose.items():
            w[:, col[name]] = np.maximum(w[:, col[name]], peak * env)
    return t, w
