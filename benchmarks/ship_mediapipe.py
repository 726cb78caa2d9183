"""Fit the shipped MediaPipe map on the appearance-family pairs, with exactly the candidates
the appearance table's folds choose among (evaluation/family_eval.py), so the model shipped
is the method the table judged on held-out families.

    .venv/bin/python benchmarks/ship_mediapipe.py ~/.cache/faceclean/families \\
        src/faceclean/models/mediapipe.npz
"""

from __future__ import annotations

import sys

from faceclean.datasets import paired
from faceclean.evaluation import family_eval as fe
from faceclean.neural import tracker_map as fit


def main(folder: str, out: str) -> None:
    pairs = paired.load(folder, require_meta=True)
    w = fit.fit(paired.with_clips(pairs), [], prefilters=fe.FOLD_PREFILTERS,
                lams=fe.FOLD_LAMBDAS, details=fe.FOLD_DETAILS, knees=fe.FOLD_KNEES,
                structured=True)  # fmt: skip
    w.config.update(trained_on=sorted({p.group for p in pairs}),
                    families=sorted({p.family for p in pairs}), pairs=len(pairs))  # fmt: skip
    w.save(out)
    print(f"wrote {out}: {w.config['structure']}")


if __name__ == "__main__":
    main(*sys.argv[1:3])
