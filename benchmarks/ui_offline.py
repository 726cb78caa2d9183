"""How soon the offline tuning page shows a change on a take of several minutes.

``faceclean ui TAKE --method one-euro`` on a synthetic performance of ``--minutes`` at
60 fps (performer.perform, seeded), opened in headless Chromium (Debian's, through
playwright, as the tests drive it). Each trial clicks the min_cutoff slider at another
place, as a user does, and reads the page's own clock: from the settings message leaving
the page to the first cleaned part arriving (the window the page shows, cleaned first) and
to the whole cleaned take arriving. Reported: the median and the worst over the trials.

    .venv/bin/python benchmarks/ui_offline.py [--minutes 5] [--trials 8] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
URL = re.compile(r"tuning page: (\S+)")


def until(tab, condition: str) -> None:
    """Wait frame by frame for a JS condition (the page's CSP forbids string eval, so this
    is one function the page runs, as tests/ui does)."""
    tab.evaluate(
        "() => new Promise((done) => { const check = () => (" + condition + ")"
        " ? done(true) : requestAnimationFrame(check); check(); })"
    )


def main() -> None:
    from headless import BROWSER_ARGS, CHROMIUM
    from playwright.sync_api import sync_playwright

    from faceclean import io
    from faceclean.datasets.performer import perform

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=5.0)
    p.add_argument("--trials", type=int, default=8)
    p.add_argument("--json")
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        take = Path(tmp) / "take.csv"
        io.save(perform(60.0 * a.minutes, seed=7, fps=60.0), take)
        ui = subprocess.Popen(
            [sys.executable, "-m", "faceclean", "ui", str(take), "--method", "one-euro",
             "--no-browser"],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
        )  # fmt: skip
        url = next(m[1] for line in ui.stdout if (m := URL.search(line)))
        window, whole = [], []
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=BROWSER_ARGS)
            tab = browser.new_page(viewport={"width": 1400, "height": 1000})
            tab.goto(url)
            until(tab, "window.faceclean && faceclean.ready && faceclean.fullSeq !== null")
            for k in range(a.trials):
                box = tab.locator("#fc-min_cutoff").bounding_box()  # (the layout may move)
                before = tab.evaluate("faceclean.setSeq")
                x = box["x"] + (0.2 + 0.6 * k / max(a.trials - 1, 1)) * box["width"]
                tab.mouse.click(x, box["y"] + box["height"] / 2)
                until(
                    tab, f"faceclean.setSeq > {before} && faceclean.state.seq >= faceclean.setSeq"
                )
                seq = tab.evaluate("faceclean.setSeq")
                until(tab, f"faceclean.fullAt[{seq}] !== undefined")
                sent, part, full = tab.evaluate(
                    f"[faceclean.sentAt[{seq}], faceclean.cleanedAt[{seq}], "
                    f"faceclean.fullAt[{seq}]]"
                )
                window.append(part - sent)
                whole.append(full - sent)
                print(f"trial {k}: window {part - sent:.0f} ms, whole take {full - sent:.0f} ms",
                      flush=True)  # fmt: skip
            browser.close()
        ui.terminate()
        ui.wait(30)
    out = {"minutes": a.minutes, "frames": int(60 * 60 * a.minutes) + 1, "trials": a.trials}
    for key, got in (("window_ms", window), ("whole_ms", whole)):
        out[key] = {"median": float(np.median(got)), "max": float(np.max(got))}
    print(json.dumps(out, indent=1))
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
