"""Guided calibration on held-out faces, rendered and photo-textured (issue 35's table).

For each face (``Scene.draw(seed, 'studio', family=..., portraits=(name,))``; a photo
face's skin is its portrait's fit, ``engine.Worker.skin``), every clip is rendered with
turning eyes (``Renderer(..., gaze=True)``, as the pairs are now) and tracked by
MediaPipe at 24 fps, the head still:

- the guided script performed late and slow (``performed``: 1 s late, then 0.8x speed,
  uneven), calibrated as ``calibrate --guided TAKE --tracker mediapipe`` does
  (``faceclean.guided.fit.guided``);
- the range-of-motion clip the pairs engine renders (``synthetic/rom.py clip``),
  calibrated as ``calibrate --rom --tracker mediapipe`` does (``calibration.calibrate``);
- the test: ``--seconds`` s windows of ``--takes`` shared iPhone takes on the same face.

Rows (scored over the test windows, MediaPipe's 51 channels; ``clean --calibration``'s
order: levels before the cleaner, an adaptation after it):

    shipped   the shipped MediaPipe cleaner alone
    rom       levels from the ROM clip, then the shipped cleaner
    guided    the shipped cleaner, then the face's guided adaptation
    oracle    the shipped cleaner, then a per-channel gain and offset fitted on the test
              windows themselves (the most a per-face level fix can do)

Columns: MSE as x raw, over all channels and per group (``family_eval.TABLE_GROUPS``),
blink closure (``metrics.blink_peaks``: output peak / true peak, pooled over the test's
blinks), prompts seen, fit seconds. Do no harm: in place of the script, a face held still
and one moving at random (``performer.perform``) for the live recording's length; what
the command says of it (``Alignment.shortfall``: it writes nothing unless ``--partial``)
and the test MSE of its ``--partial`` calibration / the shipped cleaner's.

Renders are cached under ``--cache`` (a clip's scores are a pure function of its face,
weights, times and gaze), so a rerun only refits. Run (``--table JSON``: the markdown again):

    .venv/bin/python benchmarks/guided_eval.py --faces painted:23 dressed:29 \\
        photo:41:biden photo:43:takeo --takes 2 --seconds 10 --json docs/results_guided.json
"""

from __future__ import annotations

import argparse
import glob
import hashlib
import json
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from faceclean import io, settings
from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError

RATE = 24.0  # Hz
TAKES = "../shared/data/arkit_takes/*/*.csv"
MODEL = "src/faceclean/models/mediapipe.npz"
ROWS = ("shipped", "rom", "guided", "oracle")
# docs/RESULTS.md's sections (--markdown): the table's faces, and the reserved photographs
SECTIONS = {False: ("<!-- guided calibration: begin -->", "<!-- guided calibration: end -->",
                    "Guided calibration on faces no fit saw (issue 35)"),
            True: ("<!-- guided reserved: begin -->", "<!-- guided reserved: end -->",
                   "Guided calibration on the reserved photographs (reported only)")}  # fmt: skip


@dataclass(frozen=True)
class Face:
    family: str
    seed: int
    portrait: str = ""  # the photo family's portrait

    @classmethod
    def parse(cls, spec: str, reserved: bool = False) -> Face:
        """``FAMILY:SEED`` or ``photo:SEED:PORTRAIT`` (a reserved portrait only with
        ``reserved``: a report, never a choice)."""
        from faceclean.synthetic.portrait import RESERVED

        parts = spec.split(":")
        if len(parts) not in (2, 3) or (parts[0] == "photo") != (len(parts) == 3):
            raise FacecleanError(f"face {spec!r}: FAMILY:SEED, or photo:SEED:PORTRAIT")
        if len(parts) == 3 and (parts[2] in RESERVED) != reserved:
            raise FacecleanError(f"portrait {parts[2]!r}: --reserved takes only "
                                 f"{' and '.join(RESERVED)}, and they only with it")  # fmt: skip
        return cls(parts[0], int(parts[1]), parts[2] if len(parts) == 3 else "")

    @property
    def spec(self) -> str:
        return f"{self.family}:{self.seed}" + (f":{self.portrait}" if self.portrait else "")


class Studio:
    """Renders and tracks clips on faces, each clip's scores cached under ``cache``."""

    def __init__(self, cache: Path, gaze: bool = True, reserved: bool = False) -> None:
        self.cache, self.gaze, self.reserved = cache, gaze, reserved
        self._worker = None

    def worker(self, face: Face):
        """The pairs engine's worker (head, tracker, portraits), made on the first render."""
        from faceclean.synthetic import engine

        if self._worker is None:
            args = (settings.mesh_file("ict_full.npz"), settings.tracker_model())
            if self.reserved:  # the reserved photographs as its portraits (reserved_faces.py)
                from reserved_faces import Worker

                self._worker = Worker(*args)
            else:
                cache = engine.portrait_cache()
                self._worker = engine.Worker(*args, [str(cache)] if cache.is_dir() else [])
        if face.portrait:
            ok, skipped = self._worker.usable()
            if face.portrait not in ok:
                raise FacecleanError(
                    f"portrait {face.portrait!r} is not usable (usable: {', '.join(ok)}; "
                    f"{'; '.join(skipped) or 'run make portraits'})"
                )
        return self._worker

    def render(self, face: Face, times: np.ndarray, weights: np.ndarray, tag: str) -> Animation:
        """MediaPipe's scores (N, 51) of ``weights`` (N, 52) at ``times`` on ``face``."""
        from faceclean.trackers.mediapipe import NAMES

        what = f"{face.spec} gaze={self.gaze}".encode()
        key = hashlib.sha256(what + weights.tobytes() + times.tobytes()).hexdigest()[:10]
        look = f"{face.family}{face.seed}" + (f"-{face.portrait}" if face.portrait else "")
        path = self.cache / f"{look}_{tag}{'_gaze' if self.gaze else ''}_{key}.npz"
        if path.is_file():
            return Animation(times, np.load(path)["tracked"], NAMES)
        from faceclean.synthetic.render import Renderer
        from faceclean.synthetic.scene import Scene
        from faceclean.tracking import scores

        w = self.worker(face)
        portraits = (face.portrait,) if face.portrait else ()
        scene = Scene.draw(face.seed, "studio", w.head.n_identity, face.family, portraits)
        renderer = Renderer(w.head, scene, w.skin(scene), gaze=self.gaze)
        still = np.zeros(3)  # deg: the head does not move
        tracker = w.tracker()
        try:
            frames = ((renderer.frame(weights[k], still, k), float(t)) for k, t in enumerate(times))
            out = scores(tracker, frames)  # (N, 51), NaN rows: no face
        finally:
            tracker.close()
        self.cache.mkdir(parents=True, exist_ok=True)
        np.savez(path, tracked=out)
        return Animation(times, out, NAMES)


def performed(rate: float, seconds: float, late: float = 1.0, speed: float = 0.8):
    """(take times (N,) s, script times (N,) s): a person late by ``late`` s, then at
    ``speed`` of the script's pace, uneven (+-0.12, period 7 s)."""
    tau = np.arange(int((late + seconds / (speed - 0.12) + 1.0) * rate)) / rate
    v = speed + 0.12 * np.sin(2 * np.pi * tau / 7.0)  # script s per take s
    s = np.cumsum(v) / rate
    s = np.where(tau < late, 0.0, s - np.interp(late, tau, s))
    return tau, s


def window(path: str, seconds: float, start: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """(times, weights (N, 52)) ``seconds`` of a shared take from ``start`` s, at RATE."""
    anim = io.load(path)
    values, _ = anim.arkit()
    t0 = anim.times[0] + min(start, max(0.0, anim.times[-1] - anim.times[0] - seconds))
    t = np.arange(int(seconds * RATE)) / RATE
    w = [np.interp(t + t0, anim.times, np.nan_to_num(values[:, j])) for j in range(52)]
    return t, np.clip(np.stack(w, axis=1), 0.0, 1.0)


@dataclass
class Test:
    """The test windows of one face, concatenated: (N, 51) each, and each window's rows."""

    times: list[np.ndarray]
    truth: np.ndarray
    raw: np.ndarray
    spans: list[slice]

    @property
    def ok(self) -> np.ndarray:
        return np.isfinite(self.raw).all(axis=1)


def score(test: Test, y: np.ndarray, ok: np.ndarray) -> dict:
    """MSE x raw overall and per group, and blink closure, of output ``y`` (N, 51)."""
    from faceclean.evaluation.family_eval import TABLE_GROUPS
    from faceclean.evaluation.metrics import blink_peaks
    from faceclean.trackers.mediapipe import NAMES

    ok = ok & np.isfinite(y).all(axis=1)
    out: dict = {"groups": {}}
    for g, members in (("all", NAMES), *TABLE_GROUPS.items()):
        cols = [j for j, n in enumerate(NAMES) if n in members]
        if not cols:
            continue
        raw = np.mean((test.raw[ok][:, cols] - test.truth[ok][:, cols]) ** 2)
        err = np.mean((y[ok][:, cols] - test.truth[ok][:, cols]) ** 2)
        ratio = float(err / raw) if raw > 0 else float("nan")
        if g == "all":
            out["mse_x_raw"], out["mse"] = ratio, float(err)
        else:
            out["groups"][g] = ratio
    peaks = [blink_peaks(t, y[s], test.truth[s], NAMES)
             for t, s in zip(test.times, test.spans, strict=True)]  # fmt: skip
    cat = np.concatenate(peaks)
    out["blink_closure"] = float(cat.mean()) if cat.size else float("nan")
    out["blinks"] = int(cat.size)
    return out


def oracle(test: Test, y: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """``y`` (N, 51) with a per-channel gain and offset fitted on the test itself."""
    out = np.empty_like(y)
    for j in range(y.shape[1]):
        x = np.c_[y[ok, j], np.ones(ok.sum())]
        b = np.linalg.lstsq(x, test.truth[ok, j], rcond=None)[0]
        out[:, j] = np.clip(y[:, j] * b[0] + b[1], 0, 1)
    return out


def cleaned(tracked: Animation, adjust=None) -> np.ndarray:
    """What ``clean --tracker mediapipe [--calibration]`` writes for ``tracked``: (N, 51)."""
    from faceclean.adaptation import attach
    from faceclean.guided.fit import shipped_cleaner

    cleaner, _ = shipped_cleaner("mediapipe", tracked.names)
    if adjust is not None:  # its rest reading, as the command hands it to the cleaner
        attach(cleaner, adjust.adaptation)
    if adjust is not None and not adjust.is_identity:
        tracked = tracked.with_values(adjust.apply(tracked.values, tracked.names))
    y = cleaner.clean(tracked).values
    if adjust is not None and adjust.adaptation is not None:
        y = adjust.adapt(y, tracked.names)
    return y


def fitted(take: Animation) -> dict:
    """``calibrate --guided TAKE --tracker mediapipe`` on ``take``: its fit and verdict."""
    from faceclean.guided.fit import guided

    started = time.perf_counter()
    try:
        fit = guided(take, "mediapipe")
    except FacecleanError as e:
        return {"adjust": None, "refused": str(e), "follows": False, "seen": 0, "prompts": 0}
    return {
        "adjust": fit.adjust,
        "fit_s": time.perf_counter() - started,
        "seen": fit.alignment.seen,
        "prompts": len(fit.alignment.segments),
        "follows": bool(fit.alignment.follows),
        "refused": fit.alignment.shortfall(),  # None: the command writes the file
    }


def evaluate(face: Face, studio: Studio, takes: list[str], seconds: float) -> dict:
    """One face's rows and do-no-harm clips (module docstring)."""
    from faceclean.calibration import calibrate
    from faceclean.datasets.performer import perform
    from faceclean.guided.script import TAIL, load
    from faceclean.synthetic import rom
    from faceclean.trackers.mediapipe import NAMES

    cols = [ARKIT52.index(n) for n in NAMES]
    script = load()
    tau, s = performed(RATE, script.seconds)
    guide = fitted(studio.render(face, tau, script.weights(s), "script"))
    rt, rw = rom.clip(RATE)
    started = time.perf_counter()
    rom_adjust = calibrate(studio.render(face, rt, rw, "rom"), rom=True, tracker="mediapipe")
    rom_s = time.perf_counter() - started
    clips = []
    for path in takes:
        t, w = window(path, seconds)
        clips.append((t, w[:, cols], studio.render(face, t, w, Path(path).stem)))
    edges = np.cumsum([0, *(len(c[0]) for c in clips)])
    test = Test([c[0] for c in clips], np.concatenate([c[1] for c in clips]),
                np.concatenate([c[2].values for c in clips]),
                [slice(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True)])  # fmt: skip
    ok = test.ok

    def out(adjust=None) -> np.ndarray:
        return np.concatenate([cleaned(c[2], adjust) for c in clips])

    shipped = out()
    ys = {"raw": test.raw, "shipped": shipped, "rom": out(rom_adjust)}
    ys["guided"] = out(guide["adjust"])
    ys["oracle"] = oracle(test, shipped, ok & np.isfinite(shipped).all(axis=1))
    rows = {k: score(test, y, ok) for k, y in ys.items()}
    rows["rom"]["fit_s"] = rom_s
    rows["guided"].update({k: guide[k] for k in ("seen", "prompts", "fit_s", "refused")})
    harm = {}
    n = int((script.seconds + TAIL) * RATE)
    t = np.arange(n) / RATE
    for kind in ("still", "random"):
        if kind == "still":
            w = np.zeros((n, len(ARKIT52)))
        else:
            w = perform(n / RATE, seed=1000 + face.seed, fps=RATE).values[:n]
        fit = fitted(studio.render(face, t, w, kind))
        y = out(fit["adjust"]) if fit["adjust"] is not None else shipped
        harm[kind] = {
            "follows": fit["follows"],
            "says": fit["refused"],
            "seen": fit["seen"],
            "prompts": fit["prompts"],
            "partial_x_shipped": score(test, y, ok)["mse"] / rows["shipped"]["mse"],
        }
    return {"face": face.spec, "frames": int(ok.sum()), "rows": rows, "harm": harm}


def model_version() -> dict:
    """Which shipped model the numbers are of: its last commit and sha256."""
    from faceclean.guided.fit import shipped_cleaner
    from faceclean.trackers.mediapipe import NAMES

    try:
        commit = subprocess.run(
            ["git", "log", "-1", "--format=%h %cI", "--", MODEL],
            capture_output=True, text=True, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        commit = "?"
    return {"commit": commit, "cleaner": shipped_cleaner("mediapipe", NAMES)[1]}


def finite(v):
    """``v`` with every NaN (a measure with nothing to measure) as None, for JSON."""
    if isinstance(v, dict):
        return {k: finite(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [finite(x) for x in v]
    return None if isinstance(v, float) and not np.isfinite(v) else v


def table(result: dict) -> list[str]:
    """The markdown tables of docs/CALIBRATION.md from a result (``--json``'s)."""
    from faceclean.evaluation.family_eval import TABLE_GROUPS

    def f(v, fmt: str = ".2f") -> str:
        return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else f"{v:{fmt}}"

    lines = ["| face | row | MSE x raw | " + " | ".join(TABLE_GROUPS)
             + " | blink closure | prompts seen | fit s |",
             "|---|---|---|" + "---|" * len(TABLE_GROUPS) + "---|---|---|"]  # fmt: skip
    for r in result["faces"]:
        for name in ROWS:
            row = r["rows"][name]
            seen = f"{row['seen']}/{row['prompts']}" if "prompts" in row else ""
            fit = f(row.get("fit_s"), ".3f") if "fit_s" in row else ""
            groups = " | ".join(f(row["groups"].get(g)) for g in TABLE_GROUPS)
            lines.append(f"| {r['face']} | {name} | {f(row['mse_x_raw'], '.3f')} | {groups} | "
                         f"{f(row['blink_closure'])} | {seen} | {fit} |")  # fmt: skip
    lines += ["", "| face | clip | prompts seen | the command says | its --partial calibration, "
              "test MSE x shipped |", "|---|---|---|---|---|"]  # fmt: skip
    for r in result["faces"]:
        for kind, h in r["harm"].items():
            says = h["says"] or "writes the file"
            lines.append(f"| {r['face']} | {kind} | {h['seen']}/{h['prompts']} | {says} | "
                         f"{f(h['partial_x_shipped'], '.3f')} |")  # fmt: skip
    return lines


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--faces", nargs="+", default=["painted:23", "dressed:29"],
                   help="FAMILY:SEED or photo:SEED:PORTRAIT")  # fmt: skip
    p.add_argument("--takes", type=int, default=2, help="how many shared takes to test on")
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--cache", default="/tmp/faceclean-guided-cache")
    p.add_argument("--no-gaze", action="store_true", help="render with the eyes ahead")
    p.add_argument("--reserved", action="store_true",
                   help="faces of the reserved photographs (photo:SEED:astronaut, "
                   "photo:SEED:grace_hopper): reported, never a choice")  # fmt: skip
    p.add_argument("--json", help="write the numbers here")
    p.add_argument("--markdown", metavar="PAGE", help="splice the tables into this page "
                   "(docs/RESULTS.md), a section of its own")  # fmt: skip
    p.add_argument("--table", metavar="JSON", help="print the markdown tables of a result")
    args = p.parse_args()
    if args.table:
        print("\n".join(table(json.loads(Path(args.table).read_text()))))
        return
    faces = [Face.parse(f, args.reserved) for f in args.faces]
    takes = sorted(glob.glob(TAKES))
    takes = [takes[int(k)] for k in np.linspace(0, len(takes) - 1, args.takes)]
    studio = Studio(Path(args.cache), gaze=not args.no_gaze, reserved=args.reserved)
    result = {"model": model_version(), "gaze": studio.gaze, "rate": RATE, "seconds": args.seconds,
              "takes": [Path(t).stem for t in takes], "faces": []}  # fmt: skip
    for face in faces:
        r = evaluate(face, studio, takes, args.seconds)
        result["faces"].append(r)
        rows = r["rows"]
        print(f"{face.spec:<18} " + "  ".join(
            f"{k} {rows[k]['mse_x_raw']:.3f} (blink {rows[k]['blink_closure']:.2f})"
            for k in ROWS) + f"  seen {rows['guided']['seen']}/{rows['guided']['prompts']}"
            + "".join(f"  {k} {h['partial_x_shipped']:.3f}x" for k, h in r["harm"].items()),
            flush=True)  # fmt: skip
    print(f"model: {result['model']['commit']}\n" + "\n".join(table(finite(result))))
    if args.json:
        text = json.dumps(finite(result), indent=1, allow_nan=False)
        Path(args.json).write_text(text + "\n")
    if args.markdown:
        from faceclean.evaluation.tracker_results import insert

        begin, end, title = SECTIONS[args.reserved]
        section = "\n".join([
            begin, "", f"## {title}", "",
            f"`benchmarks/guided_eval.py{' --reserved' if args.reserved else ''} --faces "
            f"{' '.join(f.spec for f in faces)} --takes {args.takes} --seconds "
            f"{args.seconds:g}` (docs/CALIBRATION.md says how each row is made; model "
            f"{result['model']['commit']}). Test: {args.seconds:g} s of each of "
            f"{', '.join(result['takes'])} on the face; MSE x raw MediaPipe, overall and per "
            "group; blink closure = output peak / true peak. Then the clips that are not the "
            "script: what the command says, and the test MSE of a `--partial` calibration "
            "from them over the shipped cleaner's.", "", *table(finite(result)), "",
            end])  # fmt: skip
        page = Path(args.markdown)
        page.write_text(insert(page.read_text(), section, begin, end))


if __name__ == "__main__":
    main()
