"""Channel registry: the canonical ARKit-52 order and name matching.

Names match case-insensitively. Accepted spellings of one channel:
ARKit camelCase (``eyeBlinkLeft``), Live Link Face PascalCase (``EyeBlinkLeft``),
``_L``/``_R`` suffixes (``eyeBlink_L``, iFacialMocap / VRM perfect sync) and
MediaPipe names (its ``_neutral`` channel is not a blendshape and is dropped).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

# ARKit ARFaceAnchor.BlendShapeLocation, canonical order (../shared/data/README.md).
ARKIT52: tuple[str, ...] = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft",
    "eyeSquintLeft", "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight",
    "eyeLookOutRight", "eyeLookUpRight", "eyeSquintRight", "eyeWideRight", "jawForward",
    "jawLeft", "jawRight", "jawOpen", "mouthClose", "mouthFunnel", "mouthPucker", "mouthLeft",
    "mouthRight", "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight",
    "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft", "mouthStretchRight",
    "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper", "mouthPressLeft",
    "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft",
    "mouthUpperUpRight", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft",
    "browOuterUpRight", "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft",
    "noseSneerRight", "tongueOut",
)  # fmt: skip

INDEX: dict[str, int] = {n: i for i, n in enumerate(ARKIT52)}

# MediaPipe's face blendshapes: ARKit names without tongueOut, plus "_neutral".
MEDIAPIPE: tuple[str, ...] = ("_neutral",) + ARKIT52[:-1]

# Tracker profiles (``calibrate --tracker``): the channels a tracker is known to under-read
# (they never pass a few hundredths), which calibration may lift to their observed top
# without a range-of-motion clip. ARKit (iPhone, Live Link Face) reads every channel's
# full range: a small peak there is a small real movement, never lifted on its own.
TRACKERS: dict[str, tuple[str, ...]] = {
    "arkit": (),
    "mediapipe": (
        "eyeWideLeft", "eyeWideRight", "cheekSquintLeft", "cheekSquintRight",
        "noseSneerLeft", "noseSneerRight",
    ),
}  # fmt: skip
DEFAULT_TRACKER = "arkit"

# Groups used for per-group tuning and for the report's figures.
GROUPS: dict[str, tuple[str, ...]] = {
    "eyes": tuple(n for n in ARKIT52 if n.startswith("eye")),
    "brows": tuple(n for n in ARKIT52 if n.startswith("brow")),
    "jaw": tuple(n for n in ARKIT52 if n.startswith("jaw")),
    "mouth": tuple(n for n in ARKIT52 if n.startswith(("mouth", "tongue"))),
    "cheeks_nose": tuple(n for n in ARKIT52 if n.startswith(("cheek", "nose"))),
}

# Live Link Face's 9 head and eye angles, radians, after the blendshapes (CSV and UDP):
# not blendshapes, cleaned by the rotation filter (filters/rotation.py), never by the
# blendshape cleaner. Their groups for per-group settings: ``head``, ``eyes``.
POSE: tuple[str, ...] = (
    "HeadYaw", "HeadPitch", "HeadRoll",
    "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
    "RightEyeYaw", "RightEyePitch", "RightEyeRoll",
)  # fmt: skip
POSE_GROUPS: dict[str, tuple[str, ...]] = {"head": POSE[:3], "eyes": POSE[3:]}

_LOWER = {n.lower(): n for n in ARKIT52}
_POSE_LOWER = {n.lower(): n for n in POSE}


def canonical(name: str) -> str | None:
    """The ARKit name for ``name`` in any accepted spelling, or None if unknown."""
    key = name.strip().lower()
    if key in _LOWER:
        return _LOWER[key]
    for suffix, side in (("_l", "left"), ("_r", "right")):
        if key.endswith(suffix):
            return _LOWER.get(key[: -len(suffix)] + side)
    return None


def channel_key(name: str) -> str:
    """What channels are matched by: the canonical ARKit name, else the name itself."""
    return canonical(name) or name.strip()


def repeated(names: Sequence[str]) -> str | None:
    """The first of ``names`` whose channel another of them names too (``jawOpen`` and
    ``JawOpen``: one channel), or None: a take, a header or a model names each once."""
    first: dict[str, str] = {}
    for n in names:
        if (k := channel_key(n)) in first:
            return first[k]
        first[k] = n
    return None


def pose_name(name: str) -> str | None:
    """The Live Link spelling (``HeadYaw``) of a head/eye angle name in any case, or None."""
    return _POSE_LOWER.get(name.strip().lower())


def group_of(name: str) -> str | None:
    """The group of a channel name: a blendshape group ("eyes", "mouth", ...) or, for a
    head/eye angle, its pose group ("head", "eyes"); None for other names."""
    c = canonical(name)
    if c is None and (p := pose_name(name)) is not None:
        return next(g for g, members in POSE_GROUPS.items() if p in members)
    return next((g for g, members in GROUPS.items() if c in members), None)


def to_side_suffix(name: str) -> str:
    """``eyeBlinkLeft`` -> ``eyeBlink_L`` (iFacialMocap / perfect-sync style)."""
    for side, suffix in (("Left", "_L"), ("Right", "_R")):
        if name.endswith(side):
            return name[: -len(side)] + suffix
    return name


def pascal(name: str) -> str:
    """``eyeBlinkLeft`` -> ``EyeBlinkLeft`` (Live Link Face CSV header style)."""
    return name[:1].upper() + name[1:]


def match(names: Sequence[str], wanted: Iterable[str] = ARKIT52) -> dict[str, int]:
    """Map each canonical name in ``wanted`` to its column in ``names`` (when present)."""
    found: dict[str, int] = {}
    for j, n in enumerate(names):
        c = canonical(n)
        if c is not None and c not in found:
            found[c] = j
    return {w: found[w] for w in wanted if w in found}
