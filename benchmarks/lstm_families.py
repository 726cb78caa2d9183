"""The paper's LSTM on the appearance-family pairs, alone and as a residual over the map.

One held-out family (default ``photo``): the map (neural/tracker_map.py, by group) and the
LSTM (neural/pair_lstm.py) train on the other families' pairs; both are judged on the held-out
family's performances (neutral holds apart), as MSE x raw MediaPipe. The residual LSTM
trains on (the map's output, truth) pairs, so it corrects what the map leaves; at run time
it steps after the map. The budget is stated by ``--epochs`` and the wall time printed.

    .venv/bin/python benchmarks/lstm_families.py ~/.cache/faceclean/families --epochs 6
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from faceclean.datasets import paired
from faceclean.datasets.paired import Pair
from faceclean.learned.lstm import Learned
from faceclean.learned.tracker_map import TrackerMap
from faceclean.neural import tracker_map as fit
from faceclean.neural.pair_lstm import train_lstm


def mse_ratio(outs, pairs) -> float:
    num = den = 0.0
    for out, p in zip(outs, pairs, strict=True):
        names = [n for n in p.tracked.names if n in p.truth.names]
        y = p.truth.arkit(names)[0]
        e = (out.arkit(names)[0] - y) ** 2
        e0 = (p.tracked.arkit(names)[0] - y) ** 2
        ok = np.isfinite(e) & np.isfinite(e0)
        num, den = num + float(e[ok].sum()), den + float(e0[ok].sum())
    return num / den


def mapped(w, p: Pair) -> Pair:
    """``p`` with its tracked take replaced by the map's output (same names and times)."""
    out = TrackerMap(weights=w, names=p.tracked.names).clean(p.tracked)
    return Pair(p.name, out, p.truth, p.group, p.setting, p.meta, p.family)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("pairs")
    ap.add_argument("--family", default="photo")
    ap.add_argument("--epochs", type=int, default=6)
    ap.add_argument("--work", default="/tmp/lstm-families")
    ap.add_argument("--json")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    pairs = paired.load(args.pairs, require_meta=True)
    train = [p for p in pairs if p.family != args.family]
    test = [p for p in pairs if p.family == args.family and p.group != "neutral"]
    val = [p for p in train if p.group == "alexdjulin"]
    fit_on = [p for p in train if p.group != "alexdjulin"]
    t0 = time.time()
    w = fit.fit(train, [], prefilters=((2.0, 50.0, 4.0),))
    res = {"raw": 1.0, "map": mse_ratio([mapped(w, p).tracked for p in test], test)}
    print(f"map: {res['map']:.3f}x raw ({time.time() - t0:.0f} s)", flush=True)
    for label, tr, va in (("lstm alone", fit_on, val),
                          ("lstm over the map", [mapped(w, p) for p in fit_on],
                           [mapped(w, p) for p in val])):  # fmt: skip
        t0 = time.time()
        path = work / f"{label.replace(' ', '-')}.npz"
        train_lstm(tr, va, path, epochs=args.epochs, threads=1)
        outs = []
        for p in test:
            src = mapped(w, p).tracked if "map" in label else p.tracked
            outs.append(Learned(model=path, names=src.names).clean(src))
        res[label] = mse_ratio(outs, test)
        res[f"{label} s"] = time.time() - t0
        print(f"{label}: {res[label]:.3f}x raw, {args.epochs} epochs in {res[f'{label} s']:.0f} s",
              flush=True)  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
