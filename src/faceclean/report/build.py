"""Assemble the self-contained HTML report: measures, curves and the 3D face view.

One file, no network when opened: the page's Content-Security-Policy allows inline
scripts and styles and ``data:`` modules only. three.js comes from the npm package
installed by ``make venv`` (node_modules/three, never copied into the repository), or,
in an installed wheel, from the copy of it the build put in ``report/vendor/`` (see
setup.py); it is inlined at report time as ``data:`` modules behind an import map.
"""

from __future__ import annotations

import base64
import html
import json
import math
import os
import re
from pathlib import Path

import faceclean
from faceclean.errors import FacecleanError
from faceclean.evaluation.comparison import Comparison, untruthed
from faceclean.face.mesh import FaceMesh
from faceclean.io.atomic import atomic_write
from faceclean.report import payload

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[2]  # src/faceclean/report -> the repository root
VENDOR = HERE / "vendor"  # in a built wheel only: vendor/three/build/*.js (setup.py)
FACE_JS = HERE / "face.js"  # the 3D face view, shared with the tuning page (faceclean.ui)
NPM_HINT = "run `make venv` (or `npm ci`) in the faceclean repository"

TRUTH_COLUMNS = (
    ("mse", "MSE", "{:.5f}"),
    ("jitter_ratio", "jitter ratio", "{:.2f}"),
    ("lag_ms", "lag (ms)", "{:.1f}"),
    ("blink_closure", "blink closure", "{:.2f}"),
)


def node_modules() -> Path:
    """The folder holding three/ (three.js): $FACECLEAN_NODE_MODULES, the repository's
    node_modules, the wheel's own copy, or the current folder's node_modules."""
    env = os.environ.get("FACECLEAN_NODE_MODULES")
    candidates = [Path(env)] if env else []
    candidates += [REPO / "node_modules", VENDOR, Path.cwd() / "node_modules"]
    for c in candidates:
        if (c / "three" / "build").is_dir():
            return c
    raise FacecleanError(f"three.js is not installed (no node_modules/three): {NPM_HINT}")


def _data_url(source: str) -> str:
    return "data:text/javascript;base64," + base64.b64encode(source.encode()).decode("ascii")


def import_map() -> tuple[str, str]:
    """(import map JSON with three.js and face.js as data: modules, three.js version)."""
    three = node_modules() / "three"
    build = three / "build"
    version = json.loads((three / "package.json").read_text()).get("version", "?")
    core = build / "three.core.js"
    names = ("three.module.min.js", "three.module.js")
    main = next((build / n for n in names if (build / n).is_file()), None)
    if main is None:
        raise FacecleanError(f"three.js build files missing in {build}: {NPM_HINT}")
    imports = {}
    source = main.read_text(encoding="utf-8")
    if core.is_file():  # r167+: the module imports its core; point it at the map's entry
        source = re.sub(r"""(['"])\./three\.core(\.min)?\.js\1""", '"three/core"', source)
        imports["three/core"] = _data_url(core.read_text(encoding="utf-8"))
    imports["three"] = _data_url(source)
    imports["faceclean/face"] = _data_url(FACE_JS.read_text(encoding="utf-8"))  # the face view
    return json.dumps({"imports": imports}), version


def _fmt(value: float, pattern: str) -> str:
    return pattern.format(value) if value is not None and math.isfinite(value) else "–"


def _table(head: list[str], rows: list[list[str]]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in rows
    )
    return f"<table><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"


def measures_html(comp: Comparison) -> str:
    """The measures section: SPEC section 5 per method against the truth when there is
    one, and always what needs no truth (jitter energy, spikes, gaps)."""
    parts = []
    if comp.truth is not None:
        from faceclean.evaluation import metrics

        rows = []
        raw = metrics.summary(comp.input, comp.truth)
        for label, anim in [("raw input", comp.input), *comp.outputs.items()]:
            got = raw if anim is comp.input else metrics.summary(anim, comp.truth)
            ratio = got["mse"] / raw["mse"] if raw["mse"] > 0 else float("nan")
            rows.append(
                [label] + [_fmt(got[k], f) for k, _, f in TRUTH_COLUMNS] + [_fmt(ratio, "{:.2f}×")]
            )
        head = ["against the truth"] + [h for _, h, _ in TRUTH_COLUMNS] + ["MSE / raw"]
        parts.append(_table(head, rows))
        parts.append(
            '<p class="note">MSE over all channels and frames (lower is better); jitter '
            "ratio: mean squared 2nd time-derivative of the output over the truth's (1 is "
            "ideal); lag: the delay that best aligns output with truth (0 ideal); blink "
            "closure: output peak over true peak per blink (1 ideal). The truth is "
            "interpolated onto the input's timestamps.</p>"
        )
    rows = []
    for label, m in untruthed(comp).items():
        rows.append(
            [
                label,
                _fmt(m["jitter_before"], "{:.4g}"),
                _fmt(m["jitter_after"], "{:.4g}"),
                _fmt(m["jitter_ratio"], "{:.3f}"),
                f"{m['spikes_removed']} of {m['spikes']}",
                f"{m['filled']} of {m['missing']}",
            ]
        )
    head = ["without a truth", "jitter energy in", "jitter energy out", "out / in"]
    parts.append(_table(head + ["spikes removed", "gaps filled"], rows))
    parts.append(
        '<p class="note">Jitter energy: mean squared 2nd time-derivative, (weight/s²)², on '
        "the real timestamps. A spike: a value more than 0.15 away from the median of its "
        "±2 neighbouring frames; removed when the output is within half that distance. "
        "Gaps: missing values of the input (tracking loss) that the output fills.</p>"
    )
    if comp.levels:
        shown = comp.levels[:12] + [f"... and {len(comp.levels) - 12} more"] * (
            len(comp.levels) > 12
        )
        items = "".join(f"<li>{html.escape(line)}</li>" for line in shown)
        parts.append(
            "<h3>Levels before the cleaner</h3>"
            '<p class="note">Every cleaner saw the input through this level mapping '
            "(faceclean calibrate, --calibration); the input shown is the raw one.</p>"
            f"<ul>{items}</ul>"
        )
    return "\n".join(parts)


def _json_script(obj) -> str:
    """JSON safe inside a <script> element."""
    text = json.dumps(obj, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace("\u2028", "\\u2028").replace("\u2029", "\\u2029")


def render(comp: Comparison, face: FaceMesh | None = None, source: str = "input") -> str:
    """The report as one HTML string."""
    from faceclean.face.mesh import stylised

    face = face if face is not None else stylised()
    imports, three_version = import_map()
    data = payload.animation(comp)
    data["mesh"] = payload.mesh(face)
    viewer = (HERE / "viewer.js").read_text(encoding="utf-8")
    if "</script" in viewer.lower():
        raise FacecleanError("internal: viewer.js must not contain '</script'")  # pragma: no cover
    a = comp.input
    sub = (
        f"{source} · {a.n_frames} frames ({int((~a.valid).sum())} missing) · "
        f"{a.duration:.2f} s · {a.rate:.1f} fps · cleaned with {comp.main}"
    )
    if len(comp.outputs) > 1:
        sub += " · compared: " + ", ".join(list(comp.outputs)[1:])
    sub += " · with a truth" if comp.truth is not None else " · no truth given"
    sub += " · levels calibrated" if comp.levels else ""
    shapes = int(face.present.sum())
    note = (
        f"Left: the input; right: cleaned with {comp.main}; both play in sync on "
        f"{face.name} ({len(face.vertices)} vertices, {shapes} of 52 ARKit shapes). "
        f"Space plays and pauses. three.js {three_version}."
    )
    if data["stride"] > 1:
        note += f" Long clip: every {data['stride']}th frame is shown."
    fields = {
        "VERSION": faceclean.__version__,
        "TITLE": html.escape(f"faceclean report: {source}"),
        "SUBTITLE": html.escape(sub),
        "MAIN": html.escape(f"cleaned: {comp.main}"),
        "FACENOTE": html.escape(note),
        "METRICS": measures_html(comp),
        "IMPORTMAP": imports,
        "DATA": _json_script(data),
        "VIEWER": viewer,
    }
    template = (HERE / "template.html").read_text(encoding="utf-8")
    return re.sub(r"__([A-Z]+)__", lambda m: fields.get(m[1], m[0]), template)


def write(
    comp: Comparison,
    path: str | os.PathLike,
    face: FaceMesh | None = None,
    source: str = "input",
) -> int:
    """Write the report atomically; returns its size in bytes."""
    text = render(comp, face, source)
    atomic_write(path, text.encode("utf-8"))
    return len(text.encode("utf-8"))
