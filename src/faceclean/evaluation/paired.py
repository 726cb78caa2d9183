"""Paired takes: a tracker's raw output and the clean animation of the same performance.

A folder of pairs holds, per pair, two takes in any format faceclean reads:

    NAME.tracked.EXT + NAME.truth.EXT    (what ``faceclean pairs`` writes), or
    NAME.raw.EXT     + NAME.clean.EXT    (a studio's raw solve and the animator's final take)

in the folder or in its subfolders (one per performer or session: the pair's group), and
optionally ``NAME.json`` (``faceclean pairs`` metadata: the performance ``group`` and the
render ``setting`` that splits use). The truth is taken at the tracked take's instants
(linear interpolation when a studio's takes were sampled apart); frames the tracker lost
stay missing. Nothing here imports torch.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from faceclean.animation import Animation
from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError
from faceclean.timing import resample

ROLES = (("tracked", "truth"), ("raw", "clean"))
EXTS = (".csv", ".json", ".npz", ".glb", ".gltf")
MAX_META = 1 << 20  # bytes of a pair's metadata JSON


@dataclass(eq=False)
class Pair:
    name: str
    tracked: Animation  # the tracker's channels, its own names
    truth: Animation  # ARKit-52 at the tracked instants
    group: str  # the performance source (split unit)
    setting: str  # render setting, or "studio-take" for a studio's own pair
    meta: dict = field(default_factory=dict)

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
            f"{root}: no pairs (NAME.tracked.csv + NAME.truth.csv, or NAME.raw.* + NAME.clean.*)"
        )
    return found


def _in_folder(root: Path) -> list[tuple[str, Path, Path, Path | None]]:
    files = {p.name: p for p in root.iterdir() if p.is_file() and not p.name.startswith(".")}
    found = []
    for fname, p in sorted(files.items()):
        for raw, clean in ROLES:
            m = re.fullmatch(rf"(.+)\.{raw}(\.[A-Za-z]+)", fname)
            if m is None or m.group(2).lower() not in EXTS:
                continue
            name = m.group(1)
            want = rf"{re.escape(name)}\.{clean}\.\w+"
            partner = [files[n] for n in sorted(files) if re.fullmatch(want, n)]
            if partner:
                found.append((name, p, partner[0], files.get(f"{name}.json")))
    return found


def load(folder: str | os.PathLike, require_meta: bool = False) -> list[Pair]:
    """Every pair of a folder (see the module docstring)."""
    from faceclean import io
    from faceclean.io.source import read_bytes, regular
    from faceclean.strict_json import loads

    pairs = []
    for name, tracked_path, truth_path, meta_path in find(folder):
        meta: dict = {}
        if meta_path is not None:
            regular(meta_path, "pair metadata file")
            meta = loads(read_bytes(meta_path, MAX_META), str(meta_path))
            if not isinstance(meta, dict):
                raise FacecleanError(f"{meta_path}: not pair metadata (not an object)")
        elif require_meta:
            continue  # a pair still being written: its JSON comes last
        tracked, truth = io.load(tracked_path), io.load(truth_path)
        job = meta.get("job") if isinstance(meta.get("job"), dict) else {}
        pairs.append(
            Pair(
                name=name,
                tracked=tracked,
                truth=aligned(truth, tracked, name),
                group=str(job.get("group", tracked_path.resolve().parent.name)),
                setting=str(job.get("setting", "studio-take")),
                meta=meta,
            )
        )
    return pairs


def aligned(truth: Animation, tracked: Animation, name: str) -> Animation:
    """The truth (ARKit-52) at the tracked take's instants."""
    y, present = truth.arkit(ARKIT52)
    if not present.any():
        raise FacecleanError(f"{name}: the truth take has no ARKit channel")
    if truth.n_frames == tracked.n_frames and np.allclose(truth.times, tracked.times, atol=1e-6):
        return Animation(tracked.times.copy(), y, ARKIT52)
    if truth.n_frames < 2:
        raise FacecleanError(f"{name}: the truth take has fewer than 2 frames")
    return Animation(tracked.times.copy(), resample(truth.times, y, tracked.times), ARKIT52)


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
