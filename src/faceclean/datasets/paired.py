"""Paired takes: a tracker's raw output and the clean animation of the same performance.

A folder of pairs holds, per pair, two takes in any format faceclean reads:

    NAME.tracked.EXT + NAME.truth.EXT    (what ``faceclean pairs`` writes), or
    NAME.raw.EXT     + NAME.clean.EXT    (a studio's raw solve and the animator's final take)

in the folder or in its subfolders (one per performer or session: the pair's group), and
optionally ``NAME.json`` (``faceclean pairs`` metadata: the performance ``group`` and the
render ``setting`` that splits use) and ``NAME.rom.tracked.EXT`` + ``NAME.rom.truth.EXT``
(the same face's calibration clip, ``faceclean pairs --rom``: a neutral hold, then a
range of motion; ``with_clips`` adds the clips to a training set).
The truth is taken at the tracked take's instants (linear interpolation when a studio's
takes were sampled apart); frames the tracker lost stay missing. Nothing here imports torch.

Every file is read through ``io.source``: a FIFO or a folder under a pair's name is
refused, not skipped, and ``NAME.json`` must be a ``faceclean-pair/1`` object. Time: a
``tracked``/``truth`` pair shares its instants (within ``TIME_TOL``); a studio's ``clean``
take must cover the ``raw`` take's instants on the same clock. Anything else is refused in
one line naming the pair.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.filters.base import MAX_ABS
from faceclean.timing import resample

ROLES = (("tracked", "truth"), ("raw", "clean"))
EXTS = (".csv", ".json", ".npz", ".glb", ".gltf")
MAX_META = 1 << 20  # bytes of a pair's metadata JSON
TIME_TOL = 5e-4  # s: a tracked/truth pair's instants agree to half a millisecond
MIN_FRAMES = 2  # frames a pair needs where the tracker read the face and the truth is whole


@dataclass(eq=False)
class Pair:
    name: str
    tracked: Animation  # the tracker's channels, its own names
    truth: Animation  # ARKit-52 at the tracked instants
    group: str  # the performance source (split unit)
    setting: str  # render setting, or "studio-take" for a studio's own pair
    meta: dict = field(default_factory=dict)
    family: str = "painted"  # appearance family (synthetic/scene.py); a studio's own: "take"
    rom: Animation | None = None  # NAME.rom.tracked.*: the same face's calibration clip
    rom_truth: Animation | None = None  # NAME.rom.truth.*: the clip's weights, at its instants

    def arrays(self, inputs: Sequence[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (N,), x (N, len(inputs)) tracked in ``inputs`` order, y (N, 52) truth)."""
        x, _ = self.tracked.arkit(inputs)
        y, _ = self.truth.arkit(ARKIT52)
        return self.tracked.times, x, y


def find(folder: str | os.PathLike) -> list[tuple[str, Path, Path, Path | None]]:
    """[(name, tracked file, truth file, metadata file or None)] in a folder and its
    immediate subfolders (one per performer or session), sorted."""
    root = Path(folder)
    if not root.is_dir():
        raise FacecleanError(f"no such folder of pairs: {root}")
    found = []
    for d in [root, *sorted(p for p in root.iterdir() if p.is_dir() and p.name[0] != ".")]:
        found += _in_folder(d)
    if not found:
        raise FacecleanError(
            f"no pairs found in {root}: {_unpaired(root)}; a pair is NAME.tracked.EXT + "
            "NAME.truth.EXT, or NAME.raw.EXT + NAME.clean.EXT"
        )
    return found


def _unpaired(root: Path) -> str:
    """What a folder without a single pair holds, in words (one line)."""
    files = [p for d in [root, *(q for q in root.iterdir() if q.is_dir())] for p in d.iterdir()
             if not p.is_dir() and not p.name.startswith(".")]  # fmt: skip
    if not files:
        return "nothing but folders" if any(root.iterdir()) else "the folder is empty"
    roles = "|".join(r for pair in ROLES for r in pair)
    lonely = sorted(p.name for p in files if re.fullmatch(rf".+\.({roles})\.[A-Za-z]+", p.name))
    said = []
    if lonely:
        said.append(f"{len(lonely)} takes without their partner ({lonely[0][:80]}, ...)")
    rest = [p.suffix.lower() or "(none)" for p in files if p.name not in lonely]
    for ext in sorted(set(rest)):
        said.append(f"{rest.count(ext)} {ext[:16]} files that are no pair's take")
    return ", ".join(said)


def _in_folder(root: Path) -> list[tuple[str, Path, Path, Path | None]]:
    # every entry but folders: a FIFO or a dangling link is found, then refused by its reader
    files = {p.name: p for p in root.iterdir() if not p.name.startswith(".") and not p.is_dir()}
    partners: dict[tuple[str, str], list[Path]] = {}  # (NAME, role) -> its files, by name:
    for fname in sorted(files):  # one pass, not one per take (10,000 takes: a second, not 1 min)
        m = re.fullmatch(rf"(.+)\.({'|'.join(c for _, c in ROLES)})\.\w+", fname)
        if m is not None:
            partners.setdefault((m.group(1), m.group(2)), []).append(files[fname])
    found = []
    for fname, p in sorted(files.items()):
        for raw, clean in ROLES:
            m = re.fullmatch(rf"(.+)\.{raw}(\.[A-Za-z]+)", fname)
            if m is None or m.group(2).lower() not in EXTS:
                continue
            name = m.group(1)
            if name.endswith(".rom"):  # NAME.rom.tracked.csv: a pair's calibration clip
                continue
            partner = partners.get((name, clean))
            if partner:
                found.append((name, p, partner[0], files.get(f"{name}.json")))
    return found


def load(folder: str | os.PathLike, require_meta: bool = False) -> list[Pair]:
    """Every pair of a folder (see the module docstring)."""
    pairs = []
    for name, tracked_path, truth_path, meta_path in find(folder):
        meta: dict = {}
        if meta_path is not None:
            meta = _meta(meta_path)
        elif require_meta:
            continue  # a pair still being written: its JSON comes last
        tracked, truth = _take(tracked_path, folder), _take(truth_path, folder)
        rom_path = tracked_path.with_name(tracked_path.name.replace(".tracked.", ".rom.tracked."))
        rom = _take(rom_path, folder) if rom_path != tracked_path and rom_path.is_file() else None
        rom_truth = None
        if rom is not None:
            clip_truth = rom_path.with_name(rom_path.name.replace(".rom.tracked.", ".rom.truth."))
            if clip_truth.is_file():
                rom_truth = aligned(_take(clip_truth, folder), rom, str(rom_path), same_times=True)
        job = meta.get("job") if isinstance(meta.get("job"), dict) else {}
        same = tracked_path.name.startswith(f"{name}.{ROLES[0][0]}.")  # tracked + truth
        pairs.append(
            Pair(
                name=name,
                tracked=tracked,
                truth=aligned(truth, tracked, str(tracked_path.with_name(name)), same),
                group=str(job.get("group", tracked_path.resolve().parent.name)),
                setting=str(job.get("setting", "studio-take")),
                meta=meta,
                family=str(job.get("family", "painted" if job else "take")),
                rom=rom,
                rom_truth=rom_truth,
            )
        )
    return pairs


def _take(path: Path, folder: str | os.PathLike) -> Animation:
    """A pair's take (``io.load``); a refusal names the file (from the pairs folder on),
    whatever the reader said (a header cell over 256 bytes: which of the pairs holds it)."""
    from faceclean import io

    try:
        return io.load(path)
    except FacecleanError as e:
        try:
            where = str(path.relative_to(folder))
        except ValueError:
            where = str(path)
        raise FacecleanError(f"{where}: {e}" if where not in str(e) else str(e)) from None


def usable(pairs: Sequence[Pair]) -> tuple[list[Pair], list[str], list[str]]:
    """(the real pairs among ``pairs`` as training reads them, why each other one is not,
    what was read as missing), the reasons one line each, naming the pair.

    A value that is infinite or beyond ``MAX_ABS`` (1e6) is no reading: it is read as
    missing, as every cleaner reads it (filters/base.py rule 2), in the tracked take, the
    truth and the calibration clip, so that no fit ever meets it. A real pair then has
    an ARKit channel in its tracked take, ``MIN_FRAMES`` frames at least where the tracker
    read the face and the truth is whole on those channels, and a tracked take that is
    not its truth (the same numbers: a folder of truth takes under tracked names)."""
    kept, skipped, notes = [], [], []
    for p in pairs:
        tracked, n_x = _readings(p.tracked)
        truth, n_y = _readings(p.truth)
        if n_x or n_y:
            notes.append(f"{p.name}: {n_x} tracked and {n_y} truth values infinite or beyond "
                         f"{MAX_ABS:g}, read as missing")  # fmt: skip
        x, present = tracked.arkit(ARKIT52)
        if not present.any():
            skipped.append(f"{p.name}: the tracked take has no ARKit channel")
            continue
        y = truth.arkit(ARKIT52)[0][:, present]
        x = x[:, present]
        good = np.isfinite(x).any(axis=1) & np.isfinite(y).all(axis=1)
        if good.sum() < MIN_FRAMES:
            skipped.append(f"{p.name}: no {MIN_FRAMES} frames where the tracker read the face "
                           "and the truth is whole")  # fmt: skip
            continue
        if np.array_equal(x[good], y[good]):
            skipped.append(f"{p.name}: the tracked take is its truth (the same numbers); a "
                           "pair needs a tracker's reading of the performance")  # fmt: skip
            continue
        rom = rom_truth = None
        if p.rom is not None and p.rom_truth is not None:
            (rom, n_r), (rom_truth, n_t) = _readings(p.rom), _readings(p.rom_truth)
            if n_r or n_t:
                notes.append(f"{p.name}.rom: {n_r + n_t} values infinite or beyond "
                             f"{MAX_ABS:g}, read as missing")  # fmt: skip
        kept.append(replace(p, tracked=tracked, truth=truth, rom=rom, rom_truth=rom_truth))
    return kept, skipped, notes


def _readings(anim: Animation) -> tuple[Animation, int]:
    """(``anim`` with its infinite or beyond-MAX_ABS values NaN, how many there were)."""
    v = anim.values
    bad = ~(np.abs(v) <= MAX_ABS) & ~np.isnan(v)
    n = int(bad.sum())
    return (anim.with_values(np.where(bad, np.nan, v)) if n else anim), n


def with_clips(pairs: Sequence[Pair]) -> list[Pair]:
    """``pairs``, then each one's calibration clip as a pair of its own (where its truth is
    there): training data that takes every channel to its full range on the same face, which
    real performances rarely do (docs/MODEL.md: on the real folds, 0.51x raw -> 0.41x)."""
    clips = [
        Pair(
            name=f"{p.name}.rom",
            tracked=p.rom,
            truth=p.rom_truth,
            group=p.group,
            setting=p.setting,
            meta={"clip": True},
            family=p.family,
        )  # fmt: skip
        for p in pairs
        if p.rom is not None and p.rom_truth is not None
    ]
    return [*pairs, *clips]


def performances(pairs: Sequence[Pair]) -> list[Pair]:
    """``pairs`` without the calibration clips ``with_clips`` added: what a validation set
    scores choices on (a clip's poses are training data; its large, isolated moves would
    hide a candidate's jitter on a performance)."""
    return [p for p in pairs if not p.meta.get("clip")]


def _meta(path: Path) -> dict:
    """A pair's ``NAME.json``: a ``faceclean-pair/1`` object, else one line."""
    from faceclean.io.source import read_json
    from faceclean.synthetic.engine import FORMAT  # the engine's own constant (numpy only)

    meta = read_json(path, "pair metadata file", MAX_META)
    if not isinstance(meta, dict):
        raise FacecleanError(f"{path}: not pair metadata (not a JSON object)")
    if meta.get("format") != FORMAT:
        said = f"format {str(meta['format'])[:40]!r}" if "format" in meta else "no 'format'"
        raise FacecleanError(
            f"{path}: not pair metadata ({said}, expected {FORMAT!r}); move it aside or "
            "write the pair again with faceclean pairs"
        )
    return meta


def aligned(truth: Animation, tracked: Animation, name: str, same_times: bool = False) -> Animation:
    """The truth (ARKit-52) at the tracked take's instants.

    ``same_times`` (a ``tracked``/``truth`` pair): the takes must share their instants
    within TIME_TOL. Otherwise (``raw``/``clean``) the truth is interpolated there and must
    cover them: no raw instant more than one truth frame step outside the truth's span.
    """
    y, present = truth.arkit(ARKIT52)
    if not present.any():
        raise FacecleanError(f"{name}: the truth take has no ARKit channel")
    t, tt = tracked.times, truth.times
    if truth.n_frames == tracked.n_frames and np.allclose(tt, t, rtol=0.0, atol=TIME_TOL):
        return Animation(t.copy(), y, ARKIT52)
    if same_times:
        raise FacecleanError(
            f"{name}: the truth take's instants are not the tracked take's "
            f"({_first_difference(tt, t)}); a pair shares its times: write it again with "
            "faceclean pairs (a studio's takes sampled apart are NAME.raw.* + NAME.clean.*)"
        )
    if truth.n_frames < 2:
        raise FacecleanError(f"{name}: the truth take has fewer than 2 frames")
    from faceclean.io.source import check_times

    check_times(tt, f"{name}: the clean take", increasing=True)  # interpolation needs order
    step = float(np.median(np.diff(tt)))  # s, one truth frame
    outside = (t < tt[0] - step) | (t > tt[-1] + step)
    if outside.any():
        raise FacecleanError(
            f"{name}: the clean take ({tt[0]:.6g} to {tt[-1]:.6g} s) does not cover "
            f"{int(outside.sum())} of the raw take's {len(t)} instants ({t[0]:.6g} to "
            f"{t[-1]:.6g} s); both need one clock from the same start: trim the raw take to "
            "the clean one, or export the clean take over the whole shot"
        )
    return Animation(t.copy(), resample(tt, y, t), ARKIT52)


def _first_difference(tt: np.ndarray, t: np.ndarray) -> str:
    """Where truth times ``tt`` first leave tracked times ``t``, in words."""
    n = min(len(tt), len(t))
    off = np.flatnonzero(~np.isclose(tt[:n], t[:n], rtol=0.0, atol=TIME_TOL))
    if len(off):
        k = int(off[0])
        return f"frame {k + 1} is at {tt[k]:.6g} s, tracked {t[k]:.6g} s"
    return f"{len(tt)} frames, tracked {len(t)}"


def split(
    pairs: Sequence[Pair], test_group: str, held_out: str
) -> tuple[list[Pair], list[Pair], list[Pair]]:
    """(train, test in training settings, test in the held-out setting): the test group's
    performances are never trained on, nor is the held-out render setting; every pair has
    its own scene seed, so no test identity is ever seen in training either."""
    train = [p for p in pairs if p.group != test_group and p.setting != held_out]
    test = [p for p in pairs if p.group == test_group and p.setting != held_out]
    test_held = [p for p in pairs if p.group == test_group and p.setting == held_out]
    return train, test, test_held


def groups(pairs: Sequence[Pair]) -> list[str]:
    return sorted({p.group for p in pairs})


def summary_json(pairs: Sequence[Pair]) -> str:
    """A one-object description of a pair set (counts by group and setting)."""
    counts: dict[str, dict[str, int]] = {}
    for p in pairs:
        counts.setdefault(p.group, {}).setdefault(p.setting, 0)
        counts[p.group][p.setting] += 1
    return json.dumps(counts, sort_keys=True)
