"""docs/ARCHITECTURE.md's dependency rules, checked on the import graph of src/faceclean.

Read from the source with ``ast`` (nothing is imported): every ``import`` and
``from ... import`` of every module, at module level and inside functions, and every
import by name (a string that names one of our modules, ``"faceclean.learned.lstm"``
or ``"faceclean.learned.lstm:Learned"``: what ``importlib`` will load).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
DOC = SRC.parent / "docs" / "ARCHITECTURE.md"
ROOT = SRC / "faceclean"

CORE = {
    "animation", "channels", "channel_map", "errors", "settings", "timing", "strict_json",
    "workers", "pose", "tracking",
}  # fmt: skip
# package (a subpackage or a top-level module) -> what it may import besides the core and
# itself, at module level or inside a function. The same table is in docs/ARCHITECTURE.md.
MAY_IMPORT: dict[str, set[str]] = {
    **{c: set() for c in CORE},
    "io": {"face"},  # gltf_take.py writes a face (stream.py takes a plain step callable)
    "face": {"io"},  # atomic writes
    # presets write atomically; tune scores with metrics; METHODS names the learned classes
    "filters": {"io", "evaluation", "learned"},
    "adjust": {"filters", "io", "adaptation"},
    "adaptation": set(),  # the guided calibration's correction after the cleaner
    "learned": {"filters", "io"},
    "resolve": {"filters", "learned", "adjust"},
    "cleaner": {"filters", "adjust", "resolve"},
    "calibration": {"adjust", "filters", "relay", "adaptation"},
    # the shipped cleaner; io: the bounded reader (a studio's own script, --script)
    "guided": {"adjust", "adaptation", "calibration", "resolve", "io"},
    "batch": {"io"},
    "relay": {"io", "faceclean", "filters"},
    "evaluation": {
        *("filters", "learned", "adjust", "resolve", "io", "cleaner", "neural", "relay"),
        "datasets",  # the takes, splits and pairs it judges on
        "synthetic",  # the still real face is rendered (its JPEG) ...
        "trackers",  # ... and tracked by MediaPipe
        "calibration",  # the tracker table's calibration row (a pair's own clip)
        "ui",  # the fuzz of the tuning page's messages (fuzz_surfaces.py, inside functions)
        "adaptation",  # plot and report hand a calibration's rest reading to the cleaner
    },
    "synthetic": {"io", "datasets", "trackers"},  # takes, pairs; the performer; MediaPipe
    # training and evaluation data: pair folders check values as the filters bound them
    # and know the engine's pair format; the simulator wraps angles as rotation does
    "datasets": {"io", "filters", "synthetic"},
    "trackers": {"relay", "io"},  # the live send; the bounded reader
    "report": {"evaluation", "face", "io", "faceclean"},
    "ui": {
        *("resolve", "adjust", "calibration", "filters", "io", "relay", "report", "face"),
        "guided",  # the page's guided calibration (the fit calibrate --guided uses)
        "adaptation",  # a guided calibration's rest reading, handed to the page's cleaner
    },
    "neural": {"filters", "learned", "datasets", "evaluation", "face", "io", "cli"},
    "cli": {"*"},  # the command line may use anything (heavy imports inside run)
    "faceclean": {"io", "cleaner"},  # the package's public face
    "__main__": {"cli"},
}
# (package, what it imports) -> the only modules of the package that may: a narrow
# allowance stays narrow (docs/ARCHITECTURE.md says why for each).
ONLY_FROM: dict[tuple[str, str], set[str]] = {
    ("io", "face"): {"faceclean.io.gltf_take"},  # a take written as an animated face
    ("filters", "evaluation"): {"faceclean.filters.tune"},  # tuning scores with metrics
    ("filters", "io"): {"faceclean.filters.presets"},  # presets written atomically
    ("filters", "learned"): {"faceclean.filters"},  # METHODS: every cleaner class by name
    ("calibration", "relay"): {"faceclean.calibration"},  # warms up as the relay does
}


def _module(path: Path) -> str:
    parts = path.relative_to(SRC).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _package(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "faceclean"


def _is_module(name: str) -> bool:
    rel = Path(*name.split(".")[1:]) if "." in name else Path()
    return (SRC / "faceclean" / rel).with_suffix(".py").is_file() or (
        SRC / "faceclean" / rel / "__init__.py"
    ).is_file()


def _imports() -> list[tuple[str, str, str | None, bool]]:
    """(importer, imported module, imported name or None, at module level)."""
    out = []
    for path in sorted(ROOT.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        top = {id(n) for n in tree.body}
        me = _module(path)
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                out += [(me, a.name, None, id(node) in top) for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                for a in node.names:
                    sub = f"{node.module}.{a.name}"
                    if node.module.startswith("faceclean") and _is_module(sub):
                        out.append((me, sub, None, id(node) in top))
                    else:
                        out.append((me, node.module, a.name, id(node) in top))
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                name, _, attr = node.value.partition(":")
                dotted = all(p.isidentifier() for p in name.split("."))
                if name.startswith("faceclean.") and dotted and _is_module(name):
                    out.append((me, name, attr or None, False))  # loaded when called
    return out


IMPORTS = _imports()
OURS = [i for i in IMPORTS if i[1].split(".")[0] == "faceclean"]


def test_every_package_has_a_rule():
    assert {_package(_module(p)) for p in ROOT.rglob("*.py")} <= set(MAY_IMPORT)


def test_torch_only_in_neural():
    bad = [(a, b) for a, b, _, _ in IMPORTS if b.split(".")[0] == "torch"]
    assert bad and all(_package(a) == "neural" for a, _ in bad), [
        x for x in bad if _package(x[0]) != "neural"
    ]


def test_no_dev_dependency_in_the_library():
    """hypothesis and pytest are dev dependencies: no module under src imports them."""
    dev = {"hypothesis", "pytest"}
    assert not [(a, b) for a, b, _, _ in IMPORTS if b.split(".")[0] in dev]


def test_no_private_name_across_packages():
    bad = []
    for a, b, name, _ in OURS:
        if _package(a) == _package(b):
            continue
        parts = b.split(".")[1:] + ([name] if name else [])
        if any(p.startswith("_") and not p.startswith("__") for p in parts):
            bad.append((a, b, name))
    assert not bad


@pytest.mark.parametrize("package", sorted(MAY_IMPORT))
def test_package_imports_only_what_its_rule_allows(package):
    allowed = MAY_IMPORT[package] | CORE | {package}
    if "*" in allowed:
        return
    bad = sorted(
        {(a, b) for a, b, _, _ in OURS if _package(a) == package and _package(b) not in allowed}
    )
    assert not bad, f"{package} may import {sorted(MAY_IMPORT[package])} and the core: {bad}"


@pytest.mark.parametrize(("package", "target"), sorted(ONLY_FROM))
def test_a_narrow_allowance_is_used_only_where_it_is_meant(package, target):
    users = {a for a, b, _, _ in OURS if _package(a) == package and _package(b) == target}
    assert users and users <= ONLY_FROM[package, target], sorted(users)


def test_no_import_cycle_at_module_level():
    """Modules importing each other at load time (a cycle Python may not resolve)."""
    graph: dict[str, set[str]] = {}
    for a, b, _, top in OURS:
        if top and a != b and not b.startswith(a + "."):
            graph.setdefault(a, set()).add(b)
    state: dict[str, int] = {}  # 1: on the path, 2: done
    cycles = []

    def visit(m: str, path: list[str]) -> None:
        state[m] = 1
        for n in sorted(graph.get(m, ())):
            parent = n.rpartition(".")[0]
            if state.get(n) == 1 and not m.startswith(n + "."):
                cycles.append([*path[path.index(n) :], n])
            elif n not in state and parent != m:
                visit(n, [*path, n])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not cycles, cycles


def test_a_repeated_file_name_says_why():
    """Two modules with one file name only where ARCHITECTURE.md's table says why."""
    names = [p.name for p in ROOT.rglob("*.py") if p.stem not in ("__init__", "__main__")]
    repeated = sorted({n for n in names if names.count(n) > 1})
    section = DOC.read_text(encoding="utf-8").split("## Repeated file names")[1].split("\n## ")[0]
    assert repeated and not [n for n in repeated if f"`{n}`" not in section]
