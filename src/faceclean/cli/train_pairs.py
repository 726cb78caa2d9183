"""``faceclean train --pairs DIR``: fit a cleaner on (tracked, truth) pairs.

``--arch rises`` (the default on pairs of several appearance families) fits the tracker
map over rises above rest only (neural/map_rises.py), its choices made leaving a look and
a source out, on every pair; ``map`` (the default on one look) the tracker map
(learned/tracker_map.py), ``ridge`` the linear baseline, ``lstm`` the paper's LSTM. The
sources named by ``--val-sources`` (the pairs' performance groups; default: the largest
one) are held out of fitting and used for early stopping and the choice of pre-filter;
pairs of one look never use the ``window`` render setting (held out for the tracker
table), while pairs of several appearance families (``pairs --families``) use every
setting: the map's choices are made leaving a family and a source out at once
(neural/map_groups.py). ``lstm`` stops after ``--patience`` epochs without a better
validation loss and writes ``OUT.last.npz`` every epoch: ``--resume OUT.last.npz``
continues a run that was stopped (``--epochs`` may be raised). A pair's calibration clip
(``pairs --rom``: its NAME.rom.tracked + NAME.rom.truth) trains with it, as a pair of its
own. The written model runs with
``--model M.npz``.

Only real pairs train (``paired.usable``): a value that is infinite or beyond 1e6 is read
as missing (said on stderr), a pair that is no tracker's reading of its truth is skipped
(said, per pair), and a folder with none left writes nothing ("no pairs found in DIR:
..."). The model is checked before it is written (``formats.write``); a refusal names the
pairs whose values were far outside a weight's range.
"""

from __future__ import annotations

import argparse
import sys


def run(args: argparse.Namespace) -> int:
    from faceclean.datasets import paired
    from faceclean.errors import FacecleanError

    if args.arch and args.arch not in ("map", "rises", "ridge", "lstm"):
        raise FacecleanError(
            f"--arch {args.arch} does not train on pairs (rises, map, ridge or lstm)"
        )
    if not args.out or not args.out.endswith(".npz"):
        raise FacecleanError("--out must end in .npz")
    from faceclean.io.paths import verb

    done = verb(args.out)  # "replaced": said, as the file goes at the end
    if args.resume:  # torch-free: a refusal is immediate
        from pathlib import Path

        last = Path(args.out).with_name(Path(args.out).stem + ".last.npz")  # train.last_path
        if args.arch != "lstm" or Path(args.resume).resolve() != last.resolve():
            raise FacecleanError(f"with --pairs, --resume continues an lstm run: give --arch "
                                 f"lstm --resume {last}")  # fmt: skip
    from faceclean.io.atomic import writable

    if args.arch != "lstm":  # lstm: OUT and OUT.last.npz, checked by cli/train.py's run
        writable(args.out)  # refused now, not after the training
    pairs = paired.load(args.pairs)
    arch = args.arch or ("rises" if len({p.family for p in pairs}) > 1 else "map")
    if len({p.family for p in pairs}) < 2:  # one look: the window setting is what is held out
        pairs = [p for p in pairs if p.setting != "window"]  # (with families: the family is)
    if not pairs:
        raise FacecleanError(f"{args.pairs}: no pairs outside the held-out render setting")
    raw = pairs
    pairs, skipped, notes = paired.usable(pairs)
    if not pairs:
        more = f"; and {len(skipped) - 3} more" if len(skipped) > 3 else ""
        raise FacecleanError(
            f"no pairs found in {args.pairs}: {len(skipped)} candidates, none a real pair: "
            + "; ".join(skipped[:3])
            + more
        )
    for line in skipped:
        print(f"skipped {line}", file=sys.stderr)
    for line in notes:
        print(f"note: {line}", file=sys.stderr)
    groups = paired.groups(pairs)
    val_groups = set(args.val_sources) if args.val_sources else set()
    unknown = val_groups - set(groups)
    if unknown:
        raise FacecleanError(
            f"--val-sources {sorted(unknown)[0]!r}: no such pair source ({', '.join(groups)})"
        )
    if arch == "rises":  # every choice on folds that leave a look and a source out
        val_groups = set()
    elif not val_groups and len(groups) > 1:
        counts = {g: sum(p.group == g for p in pairs) for g in groups}
        val_groups = {max(groups, key=lambda g: counts[g])}
    val = [p for p in pairs if p.group in val_groups]
    train = [p for p in pairs if p.group not in val_groups] or val
    clips = sum(p.rom is not None and p.rom_truth is not None for p in train + val)
    print(
        f"{len(train)} training pairs ({', '.join(sorted({p.group for p in train}))}), "
        f"{len(val)} validation ({', '.join(sorted(val_groups)) or 'none'})"
        + (f", and {clips} calibration clips" if clips else "")
    )
    train, val = paired.with_clips(train), paired.with_clips(val)

    def report(e: dict) -> None:
        if e.get("event") == "candidate" and e.get("cv"):
            print(
                f"pre-filter {e['pre']}, shrinkage {e['lam']:g}, detail "
                f"{e['detail']:g}: leaving each of {e['cv']} sources out, MSE "
                f"{e['val_mse']:.3f}x raw, jitter {e['jitter']:.2f}x",
                file=sys.stderr,
            )
        elif e.get("event") == "candidate_lag":
            print(f"pre-filter {e['pre']}, shrinkage {e['lam']:g}, detail {e['detail']:g}: "
                  f"within the best score and the jitter budget, lag {e['lag_ms']:.0f} ms",
                  file=sys.stderr)  # fmt: skip
        elif e.get("event") == "candidate":
            print(f"pre-filter {e['pre']}, shrinkage {e['lam']:g}: validation MSE "
                  f"{e['val_mse']:.5f}, jitter {e['jitter']:.2f}x", file=sys.stderr)  # fmt: skip
        elif e.get("event") == "lift":
            knee = "no blink lift" if e["knee"] is None else f"blink lift from {e['knee']:g}"
            knee += ", its top following the stream" if e.get("top") else ""
            print(f"{knee}: leaving each of {e['cv']} sources out, MSE {e['val_mse']:.3f}x "
                  f"raw, jitter {e['jitter']:.2f}x, blink closure {e['closure']:.2f}, "
                  f"blinks {e['blinks']:.2f}x raw", file=sys.stderr)  # fmt: skip
        elif e.get("event") == "lift refused":
            print(f"blink lift from {e['knee']:g} refused: the same curve at 30 and 120 fps "
                  "differs past the contract's rate clause", file=sys.stderr)  # fmt: skip
        elif e.get("event") == "rises":
            worst = max(e["worst_family"].values(), default=float("nan"))
            print(f"rises, pre-filter {e['pre']}, deadband {e['deadband']:g} (noise x"
                  f"{e['noise_band']:g}), detail "
                  f"{e['detail']:g}, shrinkage {e['lam']:g}: leaving a look and a source out, "
                  f"MSE {e['val_typical']:.3f}x raw typical, {e['val_mse']:.3f}x pooled "
                  f"({e['val_real']:.3f}x on real faces), jitter "
                  f"{e['jitter']:.2f}x, lag {e['lag']:.0f} "
                  f"ms, worst group {worst:.2f}x, at rest {e['neutral_off']:.3f} off",
                  file=sys.stderr)  # fmt: skip
        elif e.get("event") == "epoch" and arch == "lstm":
            print(f"epoch {e['epoch']}: validation MSE {e['val_mse']:.5f}", file=sys.stderr)

    from faceclean.neural import tracker_map

    if arch == "lstm":
        from faceclean.neural.pair_lstm import train_lstm

        epochs = args.epochs or 8
        try:
            best = train_lstm(train, val, args.out, epochs=epochs, seed=args.seed,
                              threads=args.threads, report=report, patience=args.patience,
                              resume=bool(args.resume))  # fmt: skip
        except FacecleanError as e:
            raise FacecleanError(f"{e}{_poisoned(raw)}") from None
        print(f"{done} {args.out}: lstm, validation MSE {best.get('val_mse', float('nan')):.5f}")
        return 0
    if arch == "rises":  # chosen on its own folds: every pair trains
        from faceclean.neural import map_rises

        w = map_rises.fit([*train, *val], report=report)
        w.config.update(selected="leave a look and a source out")
    elif arch == "ridge":
        w = tracker_map.fit_ridge(train, val)
    else:
        w = tracker_map.fit(train, val, hidden=args.hidden or 0, seed=args.seed, report=report,
                            structured=bool(getattr(args, "by_group", False)))  # fmt: skip
    if "selected" in w.config:  # chosen leaving each source out: every source trains
        w.config.update(trained_on=sorted({p.group for p in train + val}))
    else:
        w.config.update(trained_on=sorted({p.group for p in train}),
                        validated_on=sorted(val_groups))  # fmt: skip
    try:
        w.save(args.out)  # checked first: finite, and loadable as written
    except FacecleanError as e:
        raise FacecleanError(f"{e}{_poisoned(raw)}") from None
    print(f"{done} {args.out}: {arch}, {len(w.inputs)} channels, hidden {w.config['hidden']}")
    return 0


FAR = 10.0  # a value this far outside a weight's [0, 1] is no blendshape reading


def _poisoned(pairs) -> str:
    """The pairs a refused model was made from whose values lie far outside [0, 1] (the
    largest first), as the end of the refusal's line; "" where none does."""
    import numpy as np

    worst = {}
    for p in pairs:
        for a in (p.tracked.values, p.truth.values):
            with np.errstate(invalid="ignore"):
                big = np.abs(a[~np.isnan(a)])
            if big.size and big.max() > FAR:
                worst[p.name] = max(worst.get(p.name, 0.0), float(big.max()))
    if not worst:  # nothing to add: the refusal's own words say what is wrong
        return ""
    names = sorted(worst, key=lambda n: -worst[n])
    listed = ", ".join(f"{n} ({worst[n]:.3g})" for n in names[:5])
    more = f" and {len(names) - 5} more" if len(names) > 5 else ""
    return f"; made from pairs with values far outside [0, 1]: {listed}{more}"
