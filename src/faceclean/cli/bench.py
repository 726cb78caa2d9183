"""``faceclean bench [--json OUT] [--markdown FILE] [--quick]``: the runtime benchmark.

Every cleaner side by side with eager torch on its own network (faceclean.evaluation.bench).
For the headline the process runs on one core with one BLAS/OpenMP thread: the command
re-runs itself with OMP/OPENBLAS/MKL/NUMBA thread counts set to 1 before numpy loads, and
pins itself with ``os.sched_setaffinity``. Without torch our rows run alone and the table
says so.
"""

from __future__ import annotations

import argparse
from typing import Any

MAX_STREAMS = 65536  # faces at once: 8 x N x 52 float64 per frame is 218 MB there
HELP = "benchmark every cleaner's speed against the eager-torch reference"
CHILD = "FACECLEAN_BENCH_CHILD"
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
BEGIN, END = "<!-- bench:begin -->", "<!-- bench:end -->"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", metavar="OUT", help="write the full results as JSON")
    p.add_argument(
        "--markdown",
        metavar="FILE",
        help=f"write the table into FILE (between {BEGIN} and {END} if present)",
    )
    p.add_argument("--quick", action="store_true", help="tiny sizes (a smoke test, not numbers)")
    p.add_argument("--model", help="learned model .npz (default: the shipped one, else random)")
    p.add_argument(
        "--streams", default=None, help="comma-separated stream counts (default 1,64,1024)"
    )
    p.add_argument("--cpu", type=int, default=None, help="core to pin to (default: the last)")
    p.add_argument("--no-pin", action="store_true", help="run in this process, unpinned")
    p.add_argument(
        "--openblas-core",
        default="env",
        metavar="CORE",
        help="numpy's OpenBLAS kernels: 'env' (OPENBLAS_CORETYPE as set, default), "
        "'detect' (unset it: OpenBLAS detects the CPU) or a core name such as SkylakeX",
    )


def _argv(args: argparse.Namespace) -> list[str]:
    out = ["bench"]
    for key in ("json", "markdown", "model", "streams", "cpu", "openblas_core"):
        value = getattr(args, key)
        if value is not None:
            out += [f"--{key.replace('_', '-')}", str(value)]
    return out + (["--quick"] if args.quick else [])


def run(args: argparse.Namespace) -> int:
    import os
    import subprocess
    import sys

    from faceclean.errors import FacecleanError

    if not args.no_pin and os.environ.get(CHILD) != "1":
        env = dict(os.environ, **{v: "1" for v in THREAD_VARS}, **{CHILD: "1"})
        _openblas_env(env, args.openblas_core)
        return subprocess.run([sys.executable, "-m", "faceclean", *_argv(args)], env=env).returncode

    import json

    from faceclean.evaluation import bench
    from faceclean.io.atomic import atomic_write, check_writable, together

    check_writable(args.json, args.markdown)  # now, not after the measurements

    if not args.no_pin and hasattr(os, "sched_setaffinity"):
        cores = sorted(os.sched_getaffinity(0))
        cpu = cores[-1] if args.cpu is None else args.cpu
        if cpu not in cores:
            raise FacecleanError(f"--cpu {cpu}: not one of this process's cores {cores}")
        os.sched_setaffinity(0, {cpu})
    try:
        streams = tuple(int(s) for s in args.streams.split(",")) if args.streams else None
    except ValueError:
        raise FacecleanError(f"--streams {args.streams!r}: expected e.g. 1,64,1024") from None
    if streams is not None and (not streams or min(streams) < 1 or max(streams) > MAX_STREAMS):
        raise FacecleanError(f"--streams: counts from 1 to {MAX_STREAMS}")
    if args.quick:
        sizes = bench.Sizes.quick(streams or (1, 4))
    else:
        sizes = bench.Sizes(streams=streams) if streams else bench.Sizes()
    result = bench.run(sizes, args.model, progress=lambda s: print(f"  {s}", file=sys.stderr))
    table = markdown(result)
    print(table)
    from faceclean.io.paths import verb

    said = {p: verb(p) for p in (args.json, args.markdown) if p}  # never in silence
    with together():  # both written, then both renamed
        if args.json:
            atomic_write(args.json, json.dumps(result, indent=2) + "\n")
        if args.markdown:
            atomic_write(args.markdown, _spliced(args.markdown, table))
    for path, done in said.items():
        print(f"{done} {path}")
    return 0


def _spliced(path: str, table: str) -> str:
    """FILE's text with the block between the markers replaced (or a new document)."""
    from pathlib import Path

    from faceclean.io import paths, source

    p = Path(path)
    block = f"{BEGIN}\n{table}{END}\n"
    text = source.read_text(p, "markdown file") if source.named(p) else ""
    paths.rewritable(p)  # read to be spliced: this command replaces it
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        return head + block + rest.split(END, 1)[1].lstrip("\n")
    return (text + "\n" if text else "# Benchmarks\n\n") + block


def _openblas_env(env: dict[str, str], choice: str) -> None:
    """Apply --openblas-core to the child's environment: 'env' keeps OPENBLAS_CORETYPE as
    it is, 'detect' removes it (OpenBLAS picks kernels for the CPU it finds), any other
    value sets it. (Some managed machines force an older core such as Haswell: AVX2
    kernels, about 2x slower on our matrix products than the AVX-512 ones.)"""
    if choice == "detect":
        env.pop("OPENBLAS_CORETYPE", None)
    elif choice != "env":
        env["OPENBLAS_CORETYPE"] = choice


def _ratio(ours: float | None, ref: float | None) -> str:
    return f" ({ours / ref:.2f}x)" if ours and ref else ""


def markdown(result: dict[str, Any]) -> str:
    """The results table (GitHub markdown) with the machine, ratios to the reference."""
    rows = [*result["rows"]] + ([result["reference"]] if result["reference"] else [])
    refs = {"reference": result["reference"] or {}}
    refs.update({r["key"]: r for r in result["rows"] if r.get("key")})  # other references
    streams = [int(s) for s in result["sizes"]["streams"]]
    head = ["cleaner", "step p50 us", "p99 us"]
    head += [f"{s} stream{'s' * (s > 1)}: us/stream-frame" for s in streams]
    head += ["1 h of 60 fps: s", "state B/stream", "note"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        ref = refs.get(r.get("ref", "reference")) or {}
        cells = [r["name"]]
        if r["p50_us"] is None:
            cells += ["", ""]
        else:
            cells += [f"{r['p50_us']:.1f}{_ratio(r['p50_us'], ref.get('p50_us'))}"]
            cells += [f"{r['p99_us']:.1f}"]
        for s in streams:
            thr = r["throughput"].get(s) or r["throughput"].get(str(s))
            ref_thr = (ref.get("throughput") or {}).get(s) or (ref.get("throughput") or {}).get(
                str(s)
            )
            cost = 1e6 / thr if thr else None  # us per stream-frame
            ref_cost = 1e6 / ref_thr if ref_thr else None
            cells.append(f"{cost:.2f}{_ratio(cost, ref_cost)}" if cost else "")
        hour = r["hour_s"]
        cells.append(f"{hour:.2f}{_ratio(hour, ref.get('hour_s'))}" if hour else "")
        cells.append(str(r["state_bytes"]) if r["state_bytes"] else "")
        cells.append(r["note"])
        lines.append("| " + " | ".join(cells) + " |")
    m = result["machine"]
    lines += [
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores, pinned to core(s) {m['pinned_to']}, "
        f"load average {', '.join(f'{v:.2f}' for v in m['load_average'] or ())} at the end; "
        f"Python {m['python']}, numpy {m['numpy']} ({m['blas']}), numba {m['numba']}, "
        f"onnxruntime {m['onnxruntime']}, torch {m['torch']}; "
        f"a long take's clean: {m.get('whole_take', 'unknown')}; "
        f"environment {m['env']}.",
        f"Model: {result['model']['layers']} x {result['model']['hidden']} LSTM, "
        f"{result['model']['source']}. (x) = our time / the reference's (< 1 is faster). "
        f"Hour: {result['hour_extrapolated_from_s']:g} s of 60 fps cleaned, scaled x"
        f"{3600 / result['hour_extrapolated_from_s']:g}.",
    ]
    if result.get("references", "").startswith("eager torch references not run"):
        lines.append(f"No ratios: {result['references']}.")
    return "\n".join(lines) + "\n"
