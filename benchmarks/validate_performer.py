"""Compare the synthetic performer with the real clean takes.

    .venv/bin/python benchmarks/validate_performer.py [--minutes 10]

Prints one table: blink rate and timing (from eyeBlinkLeft: a blink is a rise above half
of the take's 99.9th percentile; duration is the time above half its own peak; close
and open are its 10 %-90 % rise and 90 %-10 % fall), left/right blink correlation, how
many channels move, and per channel group the median over channels of the 95th
percentile of the activation and of the absolute velocity (1/s). One column per real
source, one for the performer (``--minutes`` of 60 s takes, seeds 0, 1, ...).
"""

from __future__ import annotations

import argparse

import numpy as np

from faceclean.channels import GROUPS, INDEX
from faceclean.datasets import dataset, performer


def blinks(t: np.ndarray, b: np.ndarray) -> list[tuple[float, float, float]]:
    """(duration, close, open) in s of every blink in one eyeBlink curve."""
    level = 0.5 * np.percentile(b, 99.9)
    above = b > max(level, 0.2)
    edges = np.flatnonzero(np.diff(above.astype(int)))
    out = []
    for start, stop in zip(edges[::2] + 1, edges[1::2] + 1, strict=False):
        if not above[start]:
            continue
        lo, hi = max(start - 30, 0), min(stop + 40, len(b))
        seg, ts = b[lo:hi], t[lo:hi]
        k = int(np.argmax(seg))
        base = min(seg[: k + 1].min(), seg[k:].min())
        frac = (seg - base) / max(seg[k] - base, 1e-9)
        rise = [ts[: k + 1][np.argmax(frac[: k + 1] >= q)] for q in (0.1, 0.5, 0.9)]
        fall = [ts[k:][np.argmax(frac[k:] <= q)] for q in (0.9, 0.5, 0.1)]
        out.append((fall[1] - rise[1], rise[2] - rise[0], fall[2] - fall[0]))
    return out


def describe(anims: list) -> dict[str, float]:
    rows, minutes, corr, moving, acts, vels = [], 0.0, [], [], [], []
    for a in anims:
        x, _ = a.arkit()
        ok = ~np.isnan(x).all(1)
        x, t = x[ok], a.times[ok]
        rows += blinks(t, x[:, INDEX["eyeBlinkLeft"]])
        minutes += (t[-1] - t[0]) / 60.0
        corr.append(np.corrcoef(x[:, INDEX["eyeBlinkLeft"]], x[:, INDEX["eyeBlinkRight"]])[0, 1])
        moving.append(int((x.std(0) > 0.01).sum()))
        acts.append(x)
        v = np.diff(x, axis=0) / np.diff(t)[:, None]
        vels.append(v[np.isfinite(v).all(1)])
    b = np.array(rows) * 1000.0  # ms
    out = {
        "blinks_per_min": len(rows) / minutes,
        "blink_ms_median": np.median(b[:, 0]),
        "close_ms_median": np.median(b[:, 1]),
        "open_ms_median": np.median(b[:, 2]),
        "blink_lr_corr": float(np.median(corr)),
        "channels_moving": float(np.median(moving)),
    }
    act, vel = np.concatenate(acts), np.abs(np.concatenate(vels))
    for g, names in GROUPS.items():
        idx = [INDEX[n] for n in names]
        out[f"{g}_act_p95"] = float(np.median(np.percentile(act[:, idx], 95, axis=0)))
        out[f"{g}_vel_p95"] = float(np.median(np.percentile(vel[:, idx], 95, axis=0)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="synthetic minutes")
    args = ap.parse_args()
    takes = dataset.load_takes()
    cols = {s: describe([t.animation for t in takes if t.source == s]) for s in
            sorted({t.source for t in takes})}  # fmt: skip
    cols["all real"] = describe([t.animation for t in takes])
    synth = [performer.perform(60.0, seed=i) for i in range(int(np.ceil(args.minutes)))]
    cols["performer"] = describe(synth)
    print(f"| {'measure':<18} | " + " | ".join(f"{c:>10}" for c in cols) + " |")
    print(f"|{'-' * 20}|" + "|".join("-" * 12 for _ in cols) + "|")
    for key in cols["performer"]:
        print(f"| {key:<18} | " + " | ".join(f"{c[key]:>10.3g}" for c in cols.values()) + " |")


if __name__ == "__main__":
    main()
