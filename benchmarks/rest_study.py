"""How the map over rises finds a face's rest: the running minimum of u, or of u smoothed,
after a warm-up (issue 34, eighth round; docs/MODEL.md).

Every fold leaves one appearance family and one performance source out at once, as the
appearance table does (evaluation/family_eval.py), and fits the map over rises on the
rest with the shipped choices fixed (pre-filter (1, 10, 2), shrinkage 0.1, band 0.01
widened x16, no lift; the outputs it leaves alone chosen on the fold's own training
folds; a group they find worse than raw passes levelled, never as read: under a smoothed
rest as read kept a photographed face's resting lids), for each rest
(``map_rises.fit(rest=(tau, warm))``). Scored through the runtime's own output
(``map_features.predict``) on the held-out pairs, per family: MSE x raw over every
performance, the real ones (the shared takes), the made-up ones and each group, and a
face at rest (the worst channel's mean |output - truth| over the neutral holds after 0.5 s).

    .venv/bin/python benchmarks/rest_study.py ~/.cache/faceclean/families-net \\
        --rests 0:0 0.1:0.1 0.15:0.2 0.1:0.1:0.01  # about 15 s a rest on 2 cores
        [--plain lids]       # the lids' inputs keep the plain minimum (one rest per input)
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from faceclean.datasets import paired
from faceclean.evaluation.family_eval import MIN_TEST, NEUTRAL, SETTLE_S, TABLE_GROUPS
from faceclean.neural import map_features, map_rises
from faceclean.neural.map_groups import real

FIXED = {"lams": (0.1,), "prefilters": ((1.0, 10.0, 2.0),), "deadbands": (0.01,),
         "noise_bands": (16.0,), "knees": (None,)}  # fmt: skip


def folds(pairs):
    """(family, source, training pairs, test pairs), as the appearance table's."""
    out = []
    for fam in sorted({p.family for p in pairs}):
        for group in sorted({p.group for p in pairs if p.family == fam}):
            train = [p for p in pairs if p.family != fam and p.group != group]
            test = [p for p in pairs if p.family == fam and p.group == group]
            if len({p.group for p in train}) >= 3 and len(test) >= MIN_TEST:
                out.append((fam, group, train, test))
    return out


def study(pairs, rest: tuple, plain=()) -> dict:
    """family -> {"all", "real", "made-up", "gaze" and the other groups: MSE x raw; "rest",
    "channel"}; the groups in ``plain`` keep the plain minimum."""
    plain = [n for g in plain for n in TABLE_GROUPS[g]]
    sq: dict = {}
    at_rest: dict = {}
    for fam, group, train, test in folds(pairs):
        w = map_rises.fit(paired.with_clips(train), rest=rest, plain=plain, **FIXED)
        gaze = [w.outputs.index(n) for n in TABLE_GROUPS["gaze"] if n in w.outputs]
        for p, f in zip(test, map_features.features(w, test), strict=True):
            y = map_features.predict(w, f.u, f.r, f.e, f.t)
            if group == NEUTRAL:
                keep = f.t - f.t[0] >= SETTLE_S
                at_rest.setdefault(fam, []).append(np.abs(y[keep] - f.y[keep]).mean(axis=0))
                continue
            kind = "real" if real(p.group) else "made-up"
            e, e0 = (y - f.y) ** 2, (f.u + f.e - f.y) ** 2  # the map's, raw's (F, M)
            cell = sq.setdefault(fam, {})
            groups = [(g, [w.outputs.index(n) for n in members if n in w.outputs])
                      for g, members in TABLE_GROUPS.items() if g != "gaze"]  # fmt: skip
            for key, cols in (("all", slice(None)), (kind, slice(None)), ("gaze", gaze),
                              *groups):  # fmt: skip
                s = cell.setdefault(key, np.zeros(2))
                s += (e[:, cols].sum(), e0[:, cols].sum())
    out = {}
    for fam, cell in sq.items():
        out[fam] = {k: float(v[0] / v[1]) for k, v in cell.items()}
        if fam in at_rest:
            mean = np.mean(at_rest[fam], axis=0)
            out[fam]["rest"] = float(mean.max())
            out[fam]["channel"] = w.outputs[int(mean.argmax())]
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("pairs", help="a folder of pairs in several families (make pairs)")
    p.add_argument("--rests", nargs="+", default=["0:0", "0.15:0.2"],
                   help="TAU:WARM[:DRIFT], s, s and weight/s, each a rest to study")  # fmt: skip
    p.add_argument("--plain", nargs="*", default=[], choices=list(TABLE_GROUPS),
                   help="groups whose inputs keep the plain minimum")  # fmt: skip
    args = p.parse_args()
    pairs = paired.load(args.pairs, require_meta=True)
    keys = ("all", "real", "made-up", "gaze", *list(TABLE_GROUPS)[1:], "rest")
    print("| rest_tau, rest_warm s, rest_drift /s | family | " + " | ".join(keys) + " |")
    print("|---|---|" + "---|" * len(keys))
    for spec in args.rests:
        rest = tuple(float(v) for v in spec.split(":"))
        started = time.perf_counter()
        for fam, s in sorted(study(pairs, rest, args.plain).items()):
            cells = [f"{s[k]:.3f}" if k in s else "-" for k in keys]
            cells[-1] += f" ({s['channel']})" if "channel" in s else ""
            said = ", ".join(f"{v:g}" for v in rest)
            print(f"| {said} | {fam} | " + " | ".join(cells) + " |", flush=True)
        print(f"<!-- {spec}: {time.perf_counter() - started:.0f} s -->", flush=True)


if __name__ == "__main__":
    main()
