"""Which channel groups the MediaPipe map reads, for one face, as their own rise alone.

The shipped map's rows read each output from its neighbours too (the brows from the smile:
a habit of the training faces' readings). A face that does not share the habit reads
better from the channel's own rise above rest, gain 1 (``learned/map_weights.own_rise``).
Its guided take says which: over the script's prompts, a group in OWN_GROUPS whose own rise
reads the prompts' aims with under OWN_RATIO of the map's mean squared error, where a seen
prompt aims at it and its own rise moved there by ``calibration.MOVE_MIN``, goes into the
calibration's ``Adaptation.own`` (and out of the correction D: guided/fit.py).

Chosen on the four faces of guided/fit.py's LAMBDA: the brows' ratio 0.83 / 0.83 / 0.64 /
0.93 (painted 7, dressed 5, obama, obama3), own rise better on their speech only on
obama's (0.435 -> 0.423x raw, brows 1.58 -> 0.92x); D over own-rise brows took such faces
further over raw (biden 1.00 -> 1.47x). The jaw's, the cheeks' and the mouth's scripts read
better from their own rise on all ten faces measured and their speech worse: only the
brows (docs/CALIBRATION.md, "The brows from their own rise").
"""

from __future__ import annotations

from typing import Any

import numpy as np

from faceclean.animation import Animation
from faceclean.calibration import MOVE_MIN
from faceclean.channels import ARKIT52, GROUPS

OWN_GROUPS = ("brows",)
OWN_RATIO = 0.75


def choose(
    cleaner: Any, anim: Animation, y: np.ndarray, target: np.ndarray, weight: np.ndarray,
    present: np.ndarray, alignment: Any,
) -> tuple[tuple[str, ...], np.ndarray, dict[str, list[float]]]:  # fmt: skip
    """(the outputs read as their own rise, y (N, 52) with them so read, {group: [the map's
    mean squared error over the prompts, its own rise's]}): ``cleaner`` a fresh shipped
    cleaner (a tracker map: else none), y its output on ``anim``, target (N, 52) and
    weight (N,) the fit's, ``alignment`` the take's (guided/align.py)."""
    if not hasattr(cleaner, "set_own_rise"):
        return (), y, {}
    names = tuple(n for g in OWN_GROUPS for n in GROUPS[g] if present[ARKIT52.index(n)])
    cleaner.set_own_rise(names)
    alone, _ = cleaner.clean(anim).arkit()
    alone = np.where(anim.valid[:, None], alone, np.nan)
    use = weight > 0
    seen = {n for g in alignment.segments if g.seen for n in g.prompt.targets}
    own, y, errors = (), y.copy(), {}
    for g in OWN_GROUPS:
        cols = [ARKIT52.index(n) for n in GROUPS[g] if n in names]
        e = [round(float((weight[use, None] * (z[use][:, cols] - target[use][:, cols]) ** 2).sum()
                         / max(weight[use].sum(), 1.0)), 6)
             for z in (np.nan_to_num(y), np.nan_to_num(alone))]  # fmt: skip
        errors[g] = e
        aimed = use & (target[:, cols] > 0).any(axis=1)  # (N,) frames a prompt moves it
        moved = aimed.any() and np.nan_to_num(alone[aimed][:, cols]).max() >= MOVE_MIN
        if set(GROUPS[g]) & seen and moved and e[1] < OWN_RATIO * e[0]:
            own += tuple(ARKIT52[j] for j in cols)
            y[:, cols] = alone[:, cols]
    return own, y, errors
