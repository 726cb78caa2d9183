"""The data engine: a job is a pure function of (performance clip, seed, render setting, timing).

``plan(...)`` lists jobs in a fixed order; ``shard(jobs, i, n)`` keeps every n-th one, so any
scheduler can spread them (``--shard i/n``). ``run_job(job, out)`` renders the clip's frames
at the job's timestamps from the truth weights, tracks them with MediaPipe (or the tracker
a ``Worker`` is given: faceclean.tracking's interface), and writes one pair
(docs/FORMATS.md, "Pairs"):

    NAME.tracked.csv   plain CSV: time (s) + MediaPipe's 51 ARKit channels; lost face = empty row
    NAME.truth.csv     plain CSV: the same times + the 52 ARKit weights that drove the render
    NAME.json          what made it: job, scene record, tracker, counts (written last)

Each file is written atomically and the JSON last, so a pair with its JSON is whole; a
rerun skips it (resumable), and a kill leaves at most unfinished temporary files.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.timing import resample, stream_times
from faceclean.tracking import Tracker, scores

FORMAT = "faceclean-pair/1"
SYNTH = "synth:"  # source prefix of a synthetic performer: "synth:SEED"
SYNTH_GROUP = "synthetic"  # the performance group every synthetic performer is in
# a performer whose channels move one by one over their whole range, no habits between them
INDEPENDENT = "independent:"  # "independent:SEED", group "independent"
NEUTRAL = "neutral:"  # a face at rest (all weights 0): "neutral:", group "neutral"
POSE = ("HeadYaw", "HeadPitch", "HeadRoll")


@dataclass(frozen=True)
class Job:
    source: str  # a take's path, or "synth:SEED" (a full-range synthetic performer)
    group: str  # the performance source (a take's folder, or "synthetic"): the split unit
    start: float  # s into the source
    seconds: float
    seed: int  # the scene: identity, appearance, light, camera, noise
    setting: str  # render setting (scene.SETTINGS)
    rate: float  # Hz, the tracker's nominal frame rate
    webcam: bool  # irregular timing with dropped frames, as a webcam delivers
    family: str = "painted"  # appearance family (scene.FAMILIES)
    portrait: str = ""  # the photo family's portrait
    gaze: bool = False  # the eyeballs turn with the eyeLook weights (gaze.py); off: ahead
    # a made-up performer's opposite directions never held at once (performer.netted)
    net: bool = False

    @property
    def name(self) -> str:
        src = self.source
        for prefix in (SYNTH, INDEPENDENT, NEUTRAL):
            src = src.removeprefix(prefix)
        stem = re.sub(r"[^A-Za-z0-9_-]+", "-", Path(src or "hold").stem)
        fields = asdict(self)
        for flag in ("gaze", "net"):  # pairs made before either keep their names
            if not fields[flag]:
                del fields[flag]
        digest = hashlib.sha1(json.dumps(fields, sort_keys=True).encode()).hexdigest()[:8]
        timing = "webcam" if self.webcam else f"{self.rate:g}fps"
        look = f"{self.family}-" + (f"{self.portrait}-" if self.portrait else "")
        look += "gaze-" if self.gaze else ""
        return f"{self.group}-{stem}-{self.start:g}s-{look}{self.setting}-{timing}-{digest}"


def plan(
    takes: list[tuple[str, str, float]],
    synthetic: int,
    seconds: float,
    settings: tuple[str, ...],
    rates: tuple[float, ...],
    seed: int = 0,
    webcam_share: float = 0.25,
    held_out: tuple[str, ...] = (),
    families: tuple[str, ...] = ("painted",),
    portraits: tuple[str, ...] = (),
    independent: int = 0,
    neutral: float = 0.0,
    gaze: bool = False,
) -> list[Job]:
    """Jobs over ``takes`` [(path, group, duration s)] cut into ``seconds`` clips,
    ``synthetic`` full-range performers and ``independent`` performers whose channels move
    one by one. Each clip is rendered once in a setting drawn from ``settings`` and once
    more in each ``held_out`` setting (for evaluation), each time with a new scene
    (identity, light, camera) and a rate and timing drawn from ``seed``; its appearance
    family is dealt in turn within its source (every source in every family), and a photo
    clip's portrait in turn among ``portraits``. ``neutral`` > 0: each scene also holds a
    neutral face that many seconds (source ``neutral:``, group ``neutral``). ``gaze``: the
    eyeballs turn with the eyeLook weights (off: they look ahead, the lids alone move). Clips are
    dealt round-robin over the sources (``_round_robin``). Same arguments, same list."""
    if not (0.5 <= seconds <= 3600):
        raise FacecleanError(f"--seconds must be in [0.5, 3600], got {seconds}")
    rng = np.random.default_rng(seed)
    clips = []
    for path, group, duration in takes:
        n = max(int(duration // seconds), 1)
        clips += [(path, group, k * seconds, min(seconds, duration)) for k in range(n)]
    clips += [(f"{SYNTH}{seed * 100_000 + k}", SYNTH_GROUP, 0.0, seconds) for k in range(synthetic)]
    clips += [(f"{INDEPENDENT}{seed * 100_000 + k}", "independent", 0.0, seconds)
              for k in range(independent)]  # fmt: skip
    if "photo" in families and not portraits:
        raise FacecleanError("the photo family needs portraits (--portraits)")
    jobs = []
    dealt: dict[str, int] = {}  # clips dealt per source (each source starts one on)
    for path, group, start, length in _round_robin(clips):
        drawn = settings[rng.integers(len(settings))]
        n = dealt[group] = dealt.get(group, len(dealt)) + 1
        family = families[n % len(families)]
        portrait = ""
        if family == "photo":  # drawn, not dealt: dealt in turn, it follows the sources
            portrait = portraits[rng.integers(len(portraits))]
        for setting in (drawn, *held_out):
            job = Job(
                source=path,
                group=group,
                start=float(start),
                seconds=float(length),
                seed=int(rng.integers(2**31)),
                setting=setting,
                rate=float(rates[rng.integers(len(rates))]),
                webcam=bool(rng.random() < webcam_share),
                family=family,
                portrait=portrait,
                gaze=gaze,
                net=path.startswith((SYNTH, INDEPENDENT)),
            )
            jobs.append(job)
            if neutral > 0:  # the same face, light and camera, at rest
                jobs.append(replace(job, source=NEUTRAL, group="neutral", start=0.0,
                                    seconds=float(neutral), webcam=False, net=False))  # fmt: skip
    return jobs


def _round_robin(clips: list[tuple]) -> list[tuple]:
    """Clips dealt one group at a time (a, b, c, a, b, c, ...), so that any prefix of the
    job list, as a run that is stopped early leaves it, covers every performance source."""
    by_group: dict[str, list[tuple]] = {}
    for c in clips:
        by_group.setdefault(c[1], []).append(c)
    queues = list(by_group.values())
    out = []
    while any(queues):
        for q in queues:
            if q:
                out.append(q.pop(0))
    return out


def shard(jobs: list[Job], i: int, n: int) -> list[Job]:
    """The i-th of n interleaved shards (0 <= i < n)."""
    return jobs[i::n]


def done(job: Job, out: Path) -> bool:
    """A pair is done when all three of its files are there (a CSV lost since is made
    again, not counted: a pair is written whole or not at all, ``write_pair``)."""
    return all((out / f"{job.name}.{k}").is_file() for k in ("tracked.csv", "truth.csv", "json"))


def performance(
    job: Job, root: str | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The clip: (times (N,) s from 0, ARKit weights (N, 52), head pose (N, 3) deg or None);
    a take's relative path is read from ``root`` (the planner's folder; default: here)."""
    from faceclean import io

    if job.source.startswith(SYNTH):
        from faceclean.datasets.performer import perform

        seed = int(job.source[len(SYNTH) :])
        anim = perform(job.seconds, seed, fps=60.0, full_range=True, net=job.net)
        return anim.times, anim.values, None
    if job.source.startswith(INDEPENDENT):
        from faceclean.datasets.performer import independent

        anim = independent(job.seconds, int(job.source[len(INDEPENDENT) :]), 60.0, job.net)
        return anim.times, anim.values, None
    if job.source == NEUTRAL:
        t = np.arange(int(job.seconds * 60.0) + 1) / 60.0
        return t, np.zeros((len(t), len(ARKIT52))), None
    anim = io.load(os.path.join(root, job.source) if root else job.source)
    values, _ = anim.arkit()
    pose = _pose(anim)
    t = anim.times - anim.times[0]
    keep = (t >= job.start - 1e-9) & (t <= job.start + job.seconds + 1e-9)
    if keep.sum() < 2:
        raise FacecleanError(
            f"{job.source}: no frames in {job.start:g}-{job.start + job.seconds:g} s"
        )
    p = None if pose is None else pose[keep]
    return t[keep] - job.start, values[keep], p


def _pose(anim: Animation) -> np.ndarray | None:
    names = anim.meta.get("pose_names")
    pose = anim.meta.get("pose")
    if names is None or pose is None:
        return None
    cols = [list(names).index(n) for n in POSE if n in names]
    if len(cols) != 3:
        return None
    p = np.degrees(np.asarray(pose, np.float64)[:, cols])
    if not np.isfinite(p).any() or np.nanmax(np.abs(p)) < 1e-6:
        return None  # a take that never recorded its head
    return np.clip(p, -45.0, 45.0)


def drift(times: np.ndarray, amplitude: float, seed: int) -> np.ndarray:
    """(N, 3) deg: a seated person's slow head wander (yaw, pitch, roll), sums of slow sines."""
    rng = np.random.default_rng([seed, 11])
    out = np.zeros((len(times), 3))
    for axis, scale in enumerate((1.0, 0.6, 0.3)):
        for _ in range(3):
            f = rng.uniform(0.03, 0.35)  # Hz
            out[:, axis] += (
                scale * amplitude / 3 * np.sin(2 * np.pi * f * times + rng.uniform(0, 6.3))
            )
    return out


def frame_times(job: Job, duration: float) -> np.ndarray:
    """(K,) s: the tracker's frame instants (regular, or webcam-irregular with drops)."""
    rng = np.random.default_rng([job.seed, 5])
    if not job.webcam:
        return np.arange(int(duration * job.rate) + 1) / job.rate
    t = stream_times(0.0, duration, job.rate, 0.3, rng)
    keep = rng.random(len(t)) > 0.05  # 5 % of frames never arrive
    keep[0] = True
    return t[keep]


class Worker:
    """Everything a process loads once: the head mesh and the tracker model. ``tracker``
    makes a fresh tracker for each clip (faceclean.tracking's interface; default:
    MediaPipe's Face Landmarker at ``tracker_path``, which a photo scene's portrait fit
    uses whatever ``tracker`` is)."""

    def __init__(self, head_path: str | os.PathLike, tracker_path: str | os.PathLike,
                 portraits: list[str] | None = None, root: str | None = None, *,
                 tracker: Callable[[], Tracker] | None = None) -> None:  # fmt: skip
        from faceclean.synthetic.head import Head

        self.root = root  # where a job's relative take path is read from (a cluster worker's)
        self.head = Head.load(head_path)
        self.tracker_path = tracker_path
        if tracker is None:
            from faceclean.trackers.mediapipe import Tracker as MediaPipe

            tracker = lambda: MediaPipe(tracker_path)  # noqa: E731
        self.tracker = tracker
        probe = tracker()  # refuse a bad model file before any job runs
        self.tracker_name = probe.name  # what a pair's record says tracked it
        probe.close()
        self.portrait_sources = list(portraits or [])
        self._portraits: dict[str, np.ndarray] | None = None
        self._unreadable: list[str] = []  # a folder's files no image reader opens: skipped
        self._fitter = None

    def portraits(self) -> dict[str, np.ndarray]:
        """name -> RGB image of every portrait given (read once)."""
        if self._portraits is None:
            from faceclean.synthetic import portrait

            self._portraits = dict(portrait.load(self.portrait_sources, self._unreadable))
        return self._portraits

    def skin(self, scene):
        """The portrait's fit for a photo scene (None for any other family)."""
        if scene.family != "photo":
            return None
        from faceclean.synthetic.portrait import Fitter

        images = self.portraits()
        if scene.portrait not in images:
            raise FacecleanError(f"portrait {scene.portrait!r} is not among --portraits")
        if self._fitter is None:
            self._fitter = Fitter(self.head, self.tracker_path)
        return self._fitter.skin(scene.portrait, images[scene.portrait], scene.flip)

    def usable(self) -> tuple[list[str], list[str]]:
        """(portraits that fit, one line for each that does not: no face, too small)."""
        ok, skipped = [], []
        for name in self.portraits():  # (read first: it fills _unreadable)
            from faceclean.synthetic.scene import Scene

            try:
                self.skin(Scene.draw(0, "studio", self.head.n_identity, "photo", (name,)))
                ok.append(name)
            except FacecleanError as e:
                skipped.append(str(e))
        return ok, self._unreadable + skipped

    def scene(self, job: Job):
        from faceclean.synthetic.scene import Scene

        return Scene.draw(job.seed, job.setting, self.head.n_identity, job.family,
                          (job.portrait,) if job.portrait else ())  # fmt: skip

    def run(self, job: Job, out: Path) -> dict:
        """Render, track and write one pair; returns its metadata record."""

        src_t, src_w, src_pose = performance(job, self.root)
        times = frame_times(job, float(src_t[-1]))
        truth = resample(src_t, src_w, times)  # (K, 52), NaN across the source's own losses
        seen = ~np.all(np.isnan(truth), axis=1)
        if seen.sum() < 2:
            raise FacecleanError(f"{job.source}: fewer than 2 frames with values in the clip")
        times, truth = times[seen], np.clip(np.nan_to_num(truth[seen]), 0.0, 1.0)
        scene = self.scene(job)
        if src_pose is not None:
            pose = np.nan_to_num(resample(src_t, src_pose, times))
        else:
            pose = drift(times, scene.pose_drift, job.seed)
        tracked = self._track(scene, times, truth, pose, job.gaze)
        return write_pair(
            out,
            job.name,
            tracked,
            Animation(times, truth, ARKIT52, {"format": "csv"}),
            {
                "format": FORMAT,
                "job": asdict(job),
                "scene": scene.record(),
                "tracker": self.tracker_name,
                "frames": len(times),
                "lost": int((~tracked.valid).sum()),
                "pose": "take" if src_pose is not None else "drift",
            },
        )

    def run_rom(self, job: Job, out: Path) -> dict:
        """The pair's calibration clip (synthetic/rom.py): the same face, light and camera,
        at the job's rate, the head still but for a small drift; NAME.rom.{truth,tracked}.csv."""
        from faceclean import io
        from faceclean.synthetic import rom

        times, truth = rom.clip(job.rate)
        scene = self.scene(job)
        pose = drift(times, 0.3 * scene.pose_drift, job.seed + 1)
        tracked = self._track(scene, times, truth, pose, job.gaze)
        io.save(Animation(times, truth, ARKIT52, {"format": "csv"}), rom_path(out, job, "truth"),
                fmt="csv")  # fmt: skip
        io.save(tracked, rom_path(out, job, "tracked"), fmt="csv")  # the clip's done mark
        return {"frames": len(times), "lost": int((~tracked.valid).sum())}

    def _track(self, scene, times: np.ndarray, truth: np.ndarray, pose: np.ndarray,
               gaze: bool = False) -> Animation:  # fmt: skip
        """The tracker's scores of the rendered frames (K, C: MediaPipe's 51); a lost face
        is a NaN row."""
        from faceclean.synthetic.render import Renderer

        renderer = Renderer(self.head, scene, self.skin(scene), gaze=gaze)
        frames = ((renderer.frame(truth[k], pose[k], k), float(t)) for k, t in enumerate(times))
        tracker = self.tracker()
        try:
            tracked = scores(tracker, frames)
        finally:
            tracker.close()
        return Animation(times, tracked, tracker.names, {"format": "csv"})


def portrait_cache() -> Path:
    """The folder ``make portraits`` fills: the portraits ``faceclean pairs`` reads when
    given no ``--portraits`` (docs/DATA.md)."""
    return Path.home() / ".cache" / "faceclean" / "portraits"


def rom_path(out: Path, job: Job, kind: str) -> Path:
    """NAME.rom.truth.csv or NAME.rom.tracked.csv (the latter written last: its mark)."""
    return out / f"{job.name}.rom.{kind}.csv"


def rom_done(job: Job, out: Path) -> bool:
    return all(rom_path(out, job, k).is_file() for k in ("truth", "tracked"))


def write_pair(out: Path, name: str, tracked: Animation, truth: Animation, meta: dict) -> dict:
    """The three files of one pair, each atomically, the JSON last (the pair's 'done' mark)."""
    from faceclean import io
    from faceclean.io.atomic import atomic_write, check_writable

    files = [out / f"{name}.{k}" for k in ("tracked.csv", "truth.csv", "json")]
    check_writable(*files)  # all three or none (a folder under the JSON's name: none)
    io.save(tracked, out / f"{name}.tracked.csv", fmt="csv")
    io.save(truth, out / f"{name}.truth.csv", fmt="csv")
    atomic_write(out / f"{name}.json", json.dumps(meta, indent=1) + "\n")
    return meta
