"""The guided calibration script: timed prompts, each with the ARKit weights it aims at.

The script ships as data (``faceclean/scripts/guided.json``, format ``SCRIPT_FORMAT``)::

    {"format": "faceclean-guided-script/1", "ramp": 0.25,
     "prompts": [{"id": "smile", "start": 20.1, "duration": 1.1, "text": "Big smile",
                  "targets": {"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0}},
                 {"id": "speech", ..., "keys": [[0.0, {}], [0.25, {"jawOpen": 0.35}], ...],
                  "weight": 0.3}, ...]}

Times are seconds from the script's start. A prompt with ``targets`` eases in over its
``ramp`` (the script's unless it sets one) with a smoothstep, holds, and eases out by
``start + duration`` (synthetic/rom.py's envelope); one with ``keys`` (seconds into the
prompt, weights) is linear between its keys. Between prompts the face rests (all 0).
``weight`` (default 1) is the prompt's weight in the fit: the speech line's targets are a
guess at what a person does, so it counts less. ``Script.weights(times)`` renders the
script as an ARKit-52 take any renderer (or person) can perform.

A studio's own script (shorter, in its performers' language, its own prompts) is a file of
the same format, given with ``--script FILE`` (``load(path)``): at most ``MAX_PROMPTS``
prompts over at most ``MAX_SECONDS``, the first a neutral hold.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from faceclean.channels import ARKIT52
from faceclean.errors import FacecleanError

SCRIPT_FORMAT = "faceclean-guided-script/1"
COUNTDOWN = 3  # s counted down before a live performance starts (the terminal's, the page's)
TAIL = 3.0  # s recorded live after the script's end (a late person finishes)
SHIPPED = Path(__file__).resolve().parent.parent / "scripts" / "guided.json"
MAX_PROMPTS = 200
MAX_SECONDS = 600.0  # s a script may last (a live recording holds it whole)
MAX_BYTES = 1 << 20  # a script file
MAX_NUMBER = 1e4  # any time (s), weight or ramp a script gives: past it, a typo
MIN_DURATION = 0.3  # s a prompt lasts at least: three steps of the alignment's 10 Hz grid
_COL = {n: i for i, n in enumerate(ARKIT52)}


@dataclass(frozen=True)
class Prompt:
    id: str
    start: float  # s from the script's start
    duration: float  # s, ramps included
    text: str
    targets: dict[str, float]  # ARKit name -> weight at the hold ({} for a neutral hold)
    keys: tuple[tuple[float, dict[str, float]], ...] = ()  # (s into the prompt, weights)
    ramp: float = 0.25  # s
    weight: float = 1.0  # in the fit

    @property
    def end(self) -> float:
        return self.start + self.duration

    @property
    def channels(self) -> tuple[str, ...]:
        """The channels this prompt moves (targets, or any key's)."""
        names = set(self.targets)
        for _, w in self.keys:
            names |= set(w)
        return tuple(n for n in ARKIT52 if n in names)

    def envelope(self, u: np.ndarray) -> np.ndarray:
        """(N,) in [0, 1] at ``u`` s into the prompt: smoothstep in, hold, out."""
        r = max(min(self.ramp, self.duration / 2), 1e-6)
        env = np.clip(np.minimum(u / r, (self.duration - u) / r), 0.0, 1.0)
        return env * env * (3.0 - 2.0 * env)

    def weights(self, u: np.ndarray) -> np.ndarray:
        """(N, 52) ARKit weights at ``u`` s into the prompt (0 outside it)."""
        w = np.zeros((len(u), len(ARKIT52)))
        inside = (u >= 0) & (u <= self.duration)
        if self.keys:
            kt = np.array([k for k, _ in self.keys])
            for name in self.channels:
                kv = np.array([k.get(name, 0.0) for _, k in self.keys])
                w[:, _COL[name]] = np.where(inside, np.interp(u, kt, kv), 0.0)
        else:
            env = self.envelope(u)
            for name, v in self.targets.items():
                w[:, _COL[name]] = v * env
        return w


@dataclass(frozen=True)
class Script:
    prompts: tuple[Prompt, ...]
    title: str = ""

    @property
    def seconds(self) -> float:
        return max(p.end for p in self.prompts)

    def weights(self, times: np.ndarray) -> np.ndarray:
        """(N, 52) ARKit weights the script aims at, at ``times`` s from its start."""
        t = np.asarray(times, dtype=np.float64)
        w = np.zeros((len(t), len(ARKIT52)))
        for p in self.prompts:
            np.maximum(w, p.weights(t - p.start), out=w)
        return w

    def clip(self, rate: float) -> tuple[np.ndarray, np.ndarray]:
        """(times (N,) s from 0 at ``rate`` Hz, weights (N, 52)): the script as a take."""
        if not 1.0 <= rate <= 1000.0:
            raise FacecleanError(f"guided script: rate must be 1..1000 Hz (got {rate:g})")
        t = np.arange(int(self.seconds * rate) + 1) / rate
        return t, self.weights(t)

    def json(self) -> str:
        """The script as a file ``load`` reads (``calibrate --print-script json``)."""
        import json

        def prompt(p: Prompt) -> dict:
            d = {"id": p.id, "start": p.start, "duration": p.duration, "text": p.text,
                 "targets": p.targets, "ramp": p.ramp, "weight": p.weight}  # fmt: skip
            if p.keys:
                d["keys"] = [[u, w] for u, w in p.keys]
            return d

        doc = {"format": SCRIPT_FORMAT, "title": self.title,
               "prompts": [prompt(p) for p in self.prompts]}  # fmt: skip
        return json.dumps(doc, indent=1)

    def lines(self) -> list[str]:
        """The script as text, one prompt a line (``calibrate --print-script``)."""
        out = [f"{self.title} ({self.seconds:.1f} s, {len(self.prompts)} prompts)"]
        for p in self.prompts:
            aims = ", ".join(f"{n} {p.targets[n]:g}" for n in p.channels if n in p.targets)
            aims = aims or ("speech shapes: " + ", ".join(p.channels) if p.keys else "neutral")
            out.append(f"{p.start:6.2f} s  {p.duration:4.2f} s  {p.text:<45} [{aims}]")
        return out


def load(path: str | os.PathLike | None = None) -> Script:
    """The script at ``path`` (the shipped one when None), checked: one line if bad."""
    from faceclean.io.source import read_json

    path = Path(path) if path is not None else SHIPPED
    return from_dict(read_json(path, "guided script", MAX_BYTES), f"guided script {path.name}")


def from_dict(data: object, label: str = "guided script") -> Script:
    if not isinstance(data, dict) or data.get("format") != SCRIPT_FORMAT:
        raise FacecleanError(f"{label}: not a guided script (format {SCRIPT_FORMAT!r})")
    ramp = _number(data.get("ramp", 0.25), f"{label}: ramp")
    prompts = []
    given = data.get("prompts") or []
    if not isinstance(given, list) or len(given) > MAX_PROMPTS:
        raise FacecleanError(f"{label}: prompts is a list of at most {MAX_PROMPTS}")
    for k, p in enumerate(given):
        where = f"{label}: prompt {k + 1}"
        if not isinstance(p, dict) or not isinstance(p.get("id"), str):
            raise FacecleanError(f"{where}: an object with an id")
        if not isinstance(p.get("text", ""), str):
            raise FacecleanError(f"{where}: its text is a string")
        if not all(str(p.get(k, "")).isprintable() for k in ("id", "text")):  # shown as is
            raise FacecleanError(f"{where}: its id and text are printable characters only")
        given_keys = p.get("keys", [])
        pair = lambda k: isinstance(k, list) and len(k) == 2  # noqa: E731
        if not isinstance(given_keys, list) or not all(pair(k) for k in given_keys):
            raise FacecleanError(f"{where} keys: a list of [seconds, {{weights}}] pairs")
        keys = tuple((_number(u, f"{where} keys"), _weights(w, where)) for u, w in given_keys)
        prompts.append(
            Prompt(
                id=p["id"],
                start=_number(p.get("start"), f"{where} start"),
                duration=_number(p.get("duration"), f"{where} duration"),
                text=str(p.get("text", "")),
                targets=_weights(p.get("targets", {}), where),
                keys=keys,
                ramp=_number(p.get("ramp", ramp), f"{where} ramp"),
                weight=_number(p.get("weight", 1.0), f"{where} weight"),
            )
        )
    ids = [p.id for p in prompts]
    if len(set(ids)) < len(ids):  # a prompt is reported, and kept seen or not, by its id
        twice = next(i for i in ids if ids.count(i) > 1)
        raise FacecleanError(f"{label}: prompt id {twice!r} is given twice")
    short = next((p for p in prompts if p.duration < MIN_DURATION), None)
    if short is not None:
        raise FacecleanError(
            f"{label}: prompt {short.id!r} lasts {short.duration:g} s "
            f"(at least {MIN_DURATION:g} s: a shorter one cannot be found)"
        )
    if not prompts or not any(not p.channels for p in prompts[:1]):
        raise FacecleanError(f"{label}: needs prompts, the first a neutral hold (no targets)")
    aimed = [p for p in prompts if p.weight > 0 and max(p.targets.values(), default=0) > 0]
    if not aimed:  # nothing to align on, nothing to fit
        raise FacecleanError(f"{label}: no prompt aims at a channel above 0 (targets, weight "
                             "over 0)")  # fmt: skip
    late = next((p for p in prompts if any(u > p.duration for u, _ in p.keys)), None)
    if late is not None:
        raise FacecleanError(f"{label}: prompt {late.id!r} has a key after its "
                             f"{late.duration:g} s")  # fmt: skip
    if any(b.start < a.end for a, b in zip(prompts, prompts[1:], strict=False)):
        raise FacecleanError(f"{label}: prompts overlap or are out of order")
    if prompts[-1].end > MAX_SECONDS:
        raise FacecleanError(f"{label}: lasts {prompts[-1].end:g} s (at most {MAX_SECONDS:g})")
    title = data.get("title", "")
    if not isinstance(title, str) or not title.isprintable():
        raise FacecleanError(f"{label}: its title is a string of printable characters")
    return Script(tuple(prompts), str(data.get("title", "")))


def _number(v: object, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v < MAX_NUMBER:
        raise FacecleanError(f"{where}: expected a number from 0 to under {MAX_NUMBER:g}, "
                             f"got {v!r}")  # fmt: skip
    return float(v)


def _weights(w: object, where: str) -> dict[str, float]:
    if not isinstance(w, dict) or any(n not in _COL for n in w):
        raise FacecleanError(f"{where}: weights map ARKit names to 0..1")
    for n, v in w.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
            raise FacecleanError(f"{where} {n}: a weight from 0 to 1, got {v!r}")
    return {n: float(v) for n, v in w.items()}
