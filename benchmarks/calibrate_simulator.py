"""Compare the simulator's ``iphone`` preset with a real raw Live Link Face stream.

    .venv/bin/python benchmarks/calibrate_simulator.py [--seeds 3] [--preset iphone]

Reads ../shared/data/raw_streams/llv_dao.npz (180 frames, 60 fps, decoded UDP packets)
and the clean takes, applies the preset to every clean take, and prints one table:
jitter level (RMS of the per-frame second difference, per channel, then quartiles over
channels), the second-difference spectrum (share of its energy per frequency band, the mean
over channels of each channel's shares), exact zeros, and dropped-frame statistics
(from the frame intervals).
"""

from __future__ import annotations

import argparse

import numpy as np

from faceclean.datasets import dataset, simulate
from faceclean.settings import data_dir

BANDS = [(0.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 30.0)]  # Hz


def stats(times: np.ndarray, values: np.ndarray) -> dict[str, float]:
    """Jitter, spectrum and drop statistics of one stream (N,) s, (N, 52)."""
    ok = ~np.isnan(values).all(1)
    times, values = times[ok], values[ok]
    dt = np.diff(times)
    period = float(np.median(dt))
    steps = np.maximum(np.round(dt / period).astype(int), 1)  # 1 = no frame missing
    # Second differences over runs of regular frames only.
    regular = steps == 1
    both = regular[1:] & regular[:-1]
    d2 = (values[2:] - 2 * values[1:-1] + values[:-2])[both]
    rms = np.sqrt(np.mean(d2**2, axis=0))
    moving = values.std(0) > 1e-6
    q25, q50, q75 = np.percentile(rms[moving], [25, 50, 75])
    # Spectrum of d2 along the longest regular run (Hann window).
    edges = np.flatnonzero(np.diff(np.concatenate([[0], both.astype(int), [0]])))
    start, stop = max(zip(edges[::2], edges[1::2], strict=True), key=lambda r: r[1] - r[0])
    seg = (values[2:] - 2 * values[1:-1] + values[:-2])[start:stop]
    seg = (seg - seg.mean(0)) * np.hanning(len(seg))[:, None]
    power = np.abs(np.fft.rfft(seg[:, moving], axis=0)) ** 2  # (F, channels)
    power = (power / np.maximum(power.sum(0), 1e-30)).mean(1)  # each channel weighs the same
    freq = np.fft.rfftfreq(len(seg), period)
    share = [power[(freq >= lo) & (freq < hi)].sum() / power.sum() for lo, hi in BANDS]
    missing = steps - 1
    minutes = (times[-1] - times[0]) / 60.0
    return {
        "rate_hz": 1.0 / period,
        "d2_rms_q25": q25,
        "d2_rms_median": q50,
        "d2_rms_q75": q75,
        **{f"d2_share_{lo:g}-{hi:g}Hz": s for (lo, hi), s in zip(BANDS, share, strict=True)},
        "zero_share": float(np.mean(values == 0.0)),
        "dropped_share": float(missing.sum() / (missing.sum() + len(times))),
        "gaps_per_min": float((missing > 0).sum() / minutes),
        "mean_gap_frames": float(missing[missing > 0].mean()) if (missing > 0).any() else 0.0,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=3, help="corruptions per clean take")
    ap.add_argument("--preset", default="iphone")
    args = ap.parse_args()
    raw = np.load(data_dir() / "raw_streams" / "llv_dao.npz")
    real = stats(raw["time"], raw["weights"].astype(np.float64))
    takes = [t for t in dataset.load_takes() if t.animation.rate > 50]  # the 60 fps takes
    clean_rows, sim_rows = [], []
    for take in takes:
        clean_rows.append(stats(take.animation.times, take.animation.values))
        for seed in range(args.seeds):
            noisy, _ = simulate.corrupt(take.animation, seed, args.preset)
            sim_rows.append(stats(noisy.times, noisy.values))
    print(f"raw stream llv_dao (180 frames) vs {args.preset!r} on {len(takes)} clean 60 fps takes")
    print(f"x {args.seeds} seeds; simulated and clean columns: median [min, max] over streams\n")
    print(f"| {'measure':<22} | {'raw stream':>10} | {'simulated':>26} | {'clean takes':>26} |")
    print(f"|{'-' * 24}|{'-' * 12}|{'-' * 28}|{'-' * 28}|")
    for key, value in real.items():
        cells = []
        for rows in (sim_rows, clean_rows):
            col = np.array([r[key] for r in rows])
            cells.append(f"{np.median(col):.4g} [{col.min():.3g}, {col.max():.3g}]")
        print(f"| {key:<22} | {value:>10.4g} | {cells[0]:>26} | {cells[1]:>26} |")


if __name__ == "__main__":
    main()
