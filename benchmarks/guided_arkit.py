"""Guided calibration for ARKit input on the shared iPhone takes (issue 35, item 4).

No tracker is in the loop for ARKit, and no iPhone recorded the script. So each take's
performer is stood in for: a face that performs the script (``guided_eval.performed``: 1 s
late, then 0.9x pace, uneven) at the take's own frame rate, reading each channel as that
take's iPhone read it: at rest the take's 5th percentile ``r``, at a prompt's aim ``w``
``r + w (q - r)`` with ``q`` the take's 99.5th percentile (a channel the take moves by less
than ``MOVED``: ``r + w (1 - r)``; the lids: the take's fullest blink), plus the take's own
frame-to-frame noise (robust sigma of its differences / sqrt 2). That performance goes
through the real commands:

    faceclean calibrate --guided performed.csv -o calib.json --tracker arkit
    faceclean clean TAKE -o plain.csv                            (the shipped default)
    faceclean clean TAKE -o calibrated.csv --calibration calib.json

Per take: the prompts seen, the levels written (neutral and gain of the channels in
``SHOWN``), and the take's blinks (peaks of its own eyeBlink with prominence >=
``metrics.BLINK_PROMINENCE``) as read, cleaned, and cleaned with the calibration: their
mean height, the fullest, and the share at full closure (>= ``FULL``).

Run: .venv/bin/python benchmarks/guided_arkit.py --json docs/results_guided_arkit.json
"""

from __future__ import annotations

import argparse
import glob
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from guided_eval import performed
from scipy.signal import find_peaks

from faceclean import io
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.evaluation.metrics import BLINK_PROMINENCE
from faceclean.guided.script import TAIL, load

TAKES = "../shared/data/arkit_takes/*/*.csv"
MOVED = 0.3  # a channel whose 99.5th percentile is within this of its 5th: reach unknown
SHOWN = ("eyeBlinkLeft", "eyeBlinkRight", "eyeSquintLeft", "jawOpen", "mouthSmileLeft",
         "browInnerUp")  # fmt: skip
BLINKS = ("eyeBlinkLeft", "eyeBlinkRight")
WINDOW = 0.06  # s: a cleaned blink's peak is looked for within this of the read one
FULL = 0.95  # a blink at full closure


def blink_frames(x: np.ndarray, name: str) -> np.ndarray:
    """Frames of ``x`` (N, 52)'s blinks on lid ``name``: its peaks of prominence >=
    ``metrics.BLINK_PROMINENCE``."""
    return find_peaks(x[:, ARKIT52.index(name)], prominence=BLINK_PROMINENCE)[0]


def stand_in(take: Animation, seed: int) -> Animation:
    """The script performed by a face that reads as ``take``'s performer (docstring)."""
    x = np.nan_to_num(take.arkit()[0])
    dt = float(np.median(np.diff(take.times)))
    rest, reach = np.percentile(x, 5, axis=0), np.percentile(x, 99.5, axis=0)
    reach = np.where(reach - rest < MOVED, 1.0, reach)
    for name in BLINKS:  # a closed eye reads as the take's fullest blink
        j, peaks = ARKIT52.index(name), blink_frames(x, name)
        reach[j] = x[peaks, j].max() if len(peaks) else reach[j]
    d = np.diff(x, axis=0)
    sigma = 1.4826 * np.median(np.abs(d - np.median(d, axis=0)), axis=0) / np.sqrt(2)
    script = load()
    tau, s = performed(1.0 / dt, script.seconds + TAIL, late=1.0, speed=0.9)
    w = script.weights(s)
    rng = np.random.default_rng(seed)
    read = rest + w * (reach - rest) + rng.normal(0.0, 1.0, w.shape) * sigma
    return Animation(tau, np.clip(read, 0.0, 1.0), ARKIT52)


def faceclean(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "faceclean", *args], capture_output=True,
                          text=True)  # fmt: skip


def blinks(t: np.ndarray, raw: np.ndarray, outs: list[np.ndarray]) -> tuple[int, list[np.ndarray]]:
    """(blinks in the take, each output's peak height at each)."""
    tops = [[] for _ in outs]
    n = 0
    for name in BLINKS:
        j, peaks = ARKIT52.index(name), blink_frames(raw, name)
        n += len(peaks)
        for k, y in enumerate(outs):
            for p in peaks:
                near = np.abs(t - t[p]) <= WINDOW + 1e-9
                tops[k].append(float(np.max(y[near, j])))
    return n, [np.asarray(v) for v in tops]


def evaluate(path: str, seed: int, work: Path) -> dict:
    take = io.load(path)
    raw = np.nan_to_num(take.arkit()[0])
    io.save(stand_in(take, seed), work / "performed.csv")
    calib = work / "calib.json"
    r = faceclean("calibrate", "--guided", str(work / "performed.csv"), "-o", str(calib),
                  "--tracker", "arkit", "--partial")  # fmt: skip
    if r.returncode != 0:
        return {"take": path, "error": r.stderr.strip()}
    facts = json.loads(calib.read_text())["calibration"]
    outs = []
    for name, extra in (("plain.csv", ()), ("calibrated.csv", ("--calibration", str(calib)))):
        c = faceclean("clean", path, "-o", str(work / name), *extra)
        if c.returncode != 0:
            return {"take": path, "error": c.stderr.strip()}
        out = io.load(work / name)
        outs.append(np.stack([np.interp(take.times, out.times, v) for v in out.arkit()[0].T], 1))
    n, peaks = blinks(take.times, raw, [raw, *outs])
    full = [float(np.mean(p >= FULL)) if n else float("nan") for p in peaks]
    mean = [float(np.mean(p)) if n else float("nan") for p in peaks]
    top = [float(np.max(p)) if n else float("nan") for p in peaks]
    chans = facts["channels"]
    return {
        "take": path,
        "fps": round(1.0 / float(np.median(np.diff(take.times))), 1),
        "seen": len(facts["guided"]["seen"]),
        "prompts": len(facts["guided"]["seen"]) + len(facts["guided"]["not_seen"]),
        "levels": {
            k: {"neutral": chans[k]["neutral"], "gain": chans[k]["gain"]}
            for k in SHOWN
            if k in chans
        },  # fmt: skip
        "blinks": n,
        "blink_mean": dict(zip(("read", "cleaned", "calibrated"), mean, strict=True)),
        "blink_fullest": dict(zip(("read", "cleaned", "calibrated"), top, strict=True)),
        "blink_closed": dict(zip(("read", "cleaned", "calibrated"), full, strict=True)),
    }


def table(rows: list[dict]) -> list[str]:
    head = "| take | fps | prompts seen | " + " | ".join(f"{k}: neutral, gain" for k in SHOWN)
    head += (" | blinks | mean peak: read / cleaned / calibrated | fullest | share >= 0.95"
             " |")  # fmt: skip
    out = [head, "|" + "---|" * (len(SHOWN) + 7)]
    for r in rows:
        name = "/".join(Path(r["take"]).parts[-2:])
        if "error" in r:
            out.append(f"| {name} | {r['error']} |")
            continue
        lv = " | ".join(
            f"{r['levels'][k]['neutral']:.2f}, {r['levels'][k]['gain']:.2f}" if k in r["levels"]
            else "" for k in SHOWN)  # fmt: skip
        b = [" / ".join(f"{r[k][c]:.2f}" for c in ("read", "cleaned", "calibrated"))
             for k in ("blink_mean", "blink_fullest", "blink_closed")]  # fmt: skip
        out.append(f"| {name} | {r['fps']:g} | {r['seen']}/{r['prompts']} | {lv} | {r['blinks']} "
                   f"| {' | '.join(b)} |")  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--takes", default=TAKES, help="glob of ARKit takes")
    ap.add_argument("--json", help="write the rows here")
    ap.add_argument("--markdown", metavar="PAGE", help="splice the table into this page "
                    "(docs/RESULTS.md), a section of its own")  # fmt: skip
    args = ap.parse_args()
    rows = []
    for k, path in enumerate(sorted(glob.glob(args.takes))):
        with tempfile.TemporaryDirectory() as d:
            rows.append(evaluate(path, 1000 + k, Path(d)))
        print(json.dumps(rows[-1]), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows}, indent=1) + "\n")
    print("\n".join(table(rows)))
    if args.markdown:
        from faceclean.evaluation.tracker_results import insert

        begin, end = "<!-- guided arkit: begin -->", "<!-- guided arkit: end -->"
        section = "\n".join([
            begin, "", "## Guided calibration of ARKit input: the levels on the shared iPhone "
            "takes", "",
            "`benchmarks/guided_arkit.py`: each take's performer stood in for by a face that "
            "performs the script reading every channel as that take's iPhone did "
            "(docs/CALIBRATION.md, \"ARKit\"); `calibrate --guided --tracker arkit` on it, "
            "and the take cleaned with and without `--calibration`.", "", *table(rows), "",
            end])  # fmt: skip
        page = Path(args.markdown)
        page.write_text(insert(page.read_text(), section, begin, end))


if __name__ == "__main__":
    main()
