"""The paper's LSTM on the appearance-family pairs, alone and as a residual over the map.

One fold of the project's protocol (evaluation/family_eval.py): a look and a source held out
at once (``--family photo --source alexdjulin``). The map is the shipped method, the map
over rises (neural/map_rises.py ``fit``, choosing its own candidates on the training pairs'
folds), and the LSTM (neural/pair_lstm.py) both train on the pairs of neither that family
nor that source (with their calibration clips); the LSTMs stop early on one other source
of those pairs (``--val``, default the largest), which they then do not train on. Both are
judged on the held-out family's pairs of the held-out source (performances only, neutral
holds apart), as MSE x raw MediaPipe. The residual LSTM trains on (the map's output,
truth) pairs, so it corrects what the map leaves; at run time it steps after the map. The
budget is stated by ``--epochs`` (``--epochs-alone``, ``--patience``) and the wall time
printed. A run is resumable: the map fitted is kept in ``--work`` and each LSTM continues
from its last finished epoch there (``--fresh`` starts over), so an hours-long run can be
stopped and started again.

    .venv/bin/python benchmarks/lstm_families.py ~/.cache/faceclean/families-net \\
        --family photo --source alexdjulin --epochs 20 --json /tmp/lstm-photo-alexdjulin.json
    # a real budget, in the background (rerun the same line to continue after a stop):
    .venv/bin/python benchmarks/lstm_families.py ~/.cache/faceclean/families-net \
        --family photo --source alexdjulin --epochs 300 --patience 40 --lr 3e-4
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from pathlib import Path

import numpy as np

from faceclean.datasets import paired
from faceclean.datasets.paired import Pair, performances
from faceclean.learned.lstm import Learned
from faceclean.learned.map_weights import MapWeights
from faceclean.learned.tracker_map import TrackerMap
from faceclean.neural import map_rises
from faceclean.neural.pair_lstm import train_lstm

NEUTRAL = "neutral"  # the neutral holds' group: not a performance source


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


def split(pairs, family: str, source: str, val_source: str | None = None):
    """(train, fit_on, val, test): train has neither ``family`` nor ``source`` (with its
    clips); val is one other source of train's performances (the largest by default),
    fit_on the rest of train; test is ``family``'s performances of ``source``."""
    test = [p for p in pairs if p.family == family and p.group == source]
    train = paired.with_clips([p for p in pairs if p.family != family and p.group != source])
    if val_source is None:
        counts = Counter(p.group for p in performances(train) if p.group != NEUTRAL)
        val_source = counts.most_common(1)[0][0]
    val = [p for p in performances(train) if p.group == val_source]
    fit_on = [p for p in train if p.group != val_source]
    return train, fit_on, val, test


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("pairs")
    ap.add_argument("--family", default="photo")
    ap.add_argument("--source", default="alexdjulin")
    ap.add_argument("--val", help="the training source the LSTMs stop on (default: largest)")
    ap.add_argument("--epochs", type=int, default=20, help="the residual LSTM's epochs")
    ap.add_argument("--epochs-alone", type=int, help="the LSTM alone's (default: --epochs)")
    ap.add_argument(
        "--patience",
        type=int,
        help="stop after this many epochs without a better validation loss (default: every epoch)",
    )
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--fresh", action="store_true", help="start over, not from --work")
    ap.add_argument("--work", default="/tmp/lstm-families")
    ap.add_argument("--json")
    args = ap.parse_args()
    work = Path(args.work) / f"{args.family}-{args.source}"
    work.mkdir(parents=True, exist_ok=True)
    pairs = paired.load(args.pairs, require_meta=True)
    train, fit_on, val, test = split(pairs, args.family, args.source, args.val)
    if not test or not val:
        raise SystemExit(f"no test or validation pairs ({len(test)}, {len(val)})")
    res: dict = {"family": args.family, "source": args.source, "val": val[0].group,
                 "train": len(train), "fit_on": len(fit_on), "val_pairs": len(val),
                 "test": len(test), "raw": 1.0}  # fmt: skip
    print(f"{args.family}/{args.source}: {len(train)} training pairs (clips included), "
          f"LSTMs on {len(fit_on)}, stop on {len(val)} of {res['val']}, test {len(test)}",
          flush=True)  # fmt: skip
    t0 = time.time()
    kept = work / "map.npz"
    if kept.exists() and not args.fresh:
        w = MapWeights.load(kept)
    else:
        w = map_rises.fit(train)
        w.save(kept)
    res["map s"] = time.time() - t0
    res["map"] = mse_ratio([mapped(w, p).tracked for p in test], test)
    res["map config"] = {k: w.config.get(k) for k in ("lam", "deadband", "passed", "own_rise")}
    print(f"map (rises): {res['map']:.3f}x raw ({res['map s']:.0f} s)", flush=True)
    alone = args.epochs_alone or args.epochs
    for label, tr, va, epochs in (
            ("lstm alone", fit_on, val, alone),
            ("lstm over the map", [mapped(w, p) for p in fit_on], [mapped(w, p) for p in val],
             args.epochs)):  # fmt: skip
        t0 = time.time()
        path = work / f"{label.replace(' ', '-')}.npz"
        best = train_lstm(tr, va, path, epochs=epochs, threads=args.threads,
                          patience=args.patience, lr=args.lr, resume=not args.fresh,
                          report=lambda e: print(e, flush=True))  # fmt: skip
        outs = []
        for p in test:
            src = mapped(w, p).tracked if "map" in label else p.tracked
            outs.append(Learned(model=path, names=src.names).clean(src))
        res[label] = mse_ratio(outs, test)
        res[f"{label} s"] = time.time() - t0
        res[f"{label} epochs"] = epochs
        res[f"{label} best epoch"] = best.get("epoch")
        res[f"{label} val"] = best.get("val_mse")
        print(f"{label}: {res[label]:.3f}x raw, {epochs} epochs (best {best.get('epoch')}) "
              f"in {res[f'{label} s']:.0f} s", flush=True)  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
