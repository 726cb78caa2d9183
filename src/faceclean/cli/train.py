"""``faceclean train``: train the recurrent cleaner (CPU; data-parallel under torchrun)."""

from __future__ import annotations

import argparse
import math
import sys

HELP = "train or fine-tune a learned cleaner (adaptive, the shipped kind; or lstm, fc, gbt)"

EPILOG = """fine-tune the shipped model on your own clean takes (a folder of takes, one
subfolder per performer or app), keeping one source apart to judge it on:

  faceclean train --data my_takes --val-sources me --resume default --out mine.npz
  faceclean clean take.csv -o clean.csv --model mine.npz

--resume MODEL scores MODEL on the validation takes before the first epoch and never
writes a model worse than it (when no epoch beats it, --out is MODEL itself)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", help="folder of clean takes (default: the shared arkit_takes)")
    p.add_argument(
        "--synthetic-minutes",
        type=float,
        default=0.0,
        metavar="N",
        help="fresh synthetic-performer minutes mixed into every epoch",
    )
    p.add_argument(
        "--val-sources",
        nargs="+",
        default=[],
        metavar="SOURCE",
        help="sources (take subfolders) held out for validation "
        "(default: 20%% of every source's takes)",
    )
    p.add_argument("--epochs", type=int, default=None, help="(default: adaptive 12, lstm 40)")
    p.add_argument("--batch", type=int, default=32, help="chunks per batch (per process)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--hidden", type=int, default=None, help="(default: adaptive 32, lstm 128)")
    p.add_argument(
        "--by-group",
        action="store_true",
        help="with --pairs: fit the tracker map by output group, no offset, chosen leaving a "
        "look and a source out (docs/MODEL.md, issue 34)",
    )
    p.add_argument("--layers", type=int, default=2)
    p.add_argument("--K", type=int, default=1, help="derivative orders (paper: 1)")
    p.add_argument(
        "--output",
        choices=("additive", "gated", "rate"),
        default="additive",
        help="output head: the paper's additive residual, gated (a learned gain "
        "on the corrective derivative plus the residual), or rate (that gain as a "
        "one-pole low-pass with a learned time constant, the same at any frame rate)",
    )
    p.add_argument("--lr", type=float, default=None, help="Adam's rate (default 1e-3)")
    p.add_argument(
        "--patience",
        type=int,
        default=8,
        help="epochs without validation improvement before stopping",
    )
    p.add_argument(
        "--w-acc",
        type=float,
        default=None,
        help="weight of the second-derivative loss, s^4 (0: the paper's loss)",
    )
    p.add_argument("--w-dis", type=float, default=None, help="weight of the distance loss")
    p.add_argument(
        "--w-der", type=float, default=None, help="weight of the derivative loss (paper: 0.01)"
    )
    p.add_argument("--mesh", help="face mesh (.npz or .glb with ARKit morph targets)")
    p.add_argument("--max-batches", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads per process")
    p.add_argument(
        "--resume",
        metavar="MODEL",
        help="continue MODEL.last.npz, or fine-tune MODEL.npz ('default': the shipped "
        "model), scored first and never worsened",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar (epoch lines only)")
    p.add_argument(
        "--report",
        metavar="MODEL",
        help="no training: evaluate MODEL on the validation takes at 30/60/120 "
        "fps and webcam timing, print a markdown table",
    )
    p.add_argument(
        "--arch",
        choices=("adaptive", "lstm", "fc", "gbt", "map", "rises", "ridge"),
        default=None,
        help="adaptive (default, the shipped kind: a One Euro filter whose cut-off a GRU "
        "shared by all channels sets), lstm (the paper's), or the paper's non-recurrent "
        "baselines fc / gbt (SPEC section 3; they use --data, --val-sources, --seed, --out); "
        "with --pairs: rises (default with several appearance families: the tracker map over "
        "rises above rest only), map (default with one: the tracker map), lstm or ridge",
    )
    p.add_argument(
        "--pairs",
        metavar="DIR",
        help="train on (tracked, truth) pairs instead of simulated artefacts: a folder from "
        "'faceclean pairs', or a studio's NAME.raw.csv + NAME.clean.csv takes (docs/TRAINING.md)",
    )
    p.add_argument("--out", metavar="MODEL", help="best model (.npz)")
    # fmt: skip


def _check_numbers(args: argparse.Namespace) -> None:
    """One line for a number no training means (it was taken, or meant something else:
    --epochs -1 ran none and said it wrote a model; --hidden 0 meant 128)."""
    import math

    from faceclean.errors import FacecleanError, seed

    seed(args.seed, "--seed")  # every generator takes such a seed, and no other
    for flag, v in (("--epochs", args.epochs), ("--patience", args.patience),
                    ("--batch", args.batch), ("--hidden", args.hidden),
                    ("--layers", args.layers), ("--K", args.K)):  # fmt: skip
        if v is not None and v < 1:
            raise FacecleanError(f"{flag} must be a whole number of at least 1, got {v}")
    for flag, v in (("--lr", args.lr), ("--w-acc", args.w_acc), ("--w-dis", args.w_dis),
                    ("--w-der", args.w_der)):  # fmt: skip
        if v is not None and not (math.isfinite(v) and v >= 0 and (flag != "--lr" or v > 0)):
            least = "over" if flag == "--lr" else "of at least"
            raise FacecleanError(f"{flag} must be a finite number {least} 0, got {v}")


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from faceclean import workers
    from faceclean.errors import FacecleanError

    _check_numbers(args)  # every path's numbers, before any work
    args.threads, note = workers.count(args.threads, None, flag="--threads")
    if note:
        print(note, file=sys.stderr)
    if args.pairs:
        from faceclean.cli import train_pairs

        for flag, v in (("--data", args.data), ("--mesh", args.mesh), ("--report", args.report),
                        ("--synthetic-minutes", args.synthetic_minutes)):  # fmt: skip
            if v:  # a take folder's options: with pairs they were ignored in silence
                raise FacecleanError(f"{flag} trains on takes, not with --pairs: drop one")

        if args.arch == "lstm" and args.out and args.out.endswith(".npz"):
            check_outputs(args)  # OUT and OUT.last.npz, which a resumed run rewrites
        return train_pairs.run(args)
    args.arch = args.arch or "adaptive"
    if args.arch in ("map", "rises", "ridge"):
        raise FacecleanError(f"--arch {args.arch} trains on pairs: give --pairs DIR")
    if args.report:
        print(_report(args))
        return 0
    if not args.out or not args.out.endswith(".npz"):
        raise FacecleanError("--out must end in .npz")
    check_outputs(args)  # before torch is imported: a refusal is immediate

    from tqdm import tqdm

    from faceclean.neural.losses import Weights
    from faceclean.neural.train import Config, train

    if args.arch == "adaptive":
        return _adaptive(args)
    if args.arch != "lstm":
        return _baseline(args)
    args.epochs = 40 if args.epochs is None else args.epochs
    args.hidden = 128 if args.hidden is None else args.hidden
    args.lr = 1e-3 if args.lr is None else args.lr
    if args.epochs < 1 or args.batch < 1:
        raise FacecleanError("--epochs and --batch must be at least 1")
    weights = Weights()
    if args.w_acc is not None:
        weights = dataclasses.replace(weights, acc=args.w_acc)
    if args.w_dis is not None:
        weights = dataclasses.replace(weights, dis=args.w_dis)
    if args.w_der is not None:
        weights = dataclasses.replace(weights, der=args.w_der)
    cfg = Config(
        out=args.out, data=args.data, val_sources=tuple(args.val_sources),
        synthetic_minutes=args.synthetic_minutes, epochs=args.epochs, batch=args.batch,
        seed=args.seed, K=args.K, hidden=args.hidden, layers=args.layers, lr=args.lr,
        output=args.output,
        patience=args.patience, weights=weights, mesh=args.mesh, resume=args.resume,
        max_batches=args.max_batches, threads=args.threads,
    )  # fmt: skip
    bar: list[tqdm] = []

    def report(e: dict) -> None:
        if e["event"] == "start":
            print(f"train on {', '.join(e['train_sources'])}; validate on "
                  f"{', '.join(e['val_sources']) or '-'}; {e['world']} process(es)",
                  file=sys.stderr)  # fmt: skip
        elif e["event"] == "batch" and not args.quiet:
            if e["i"] == 0:
                bar.append(tqdm(total=e["n"], desc=f"epoch {e['epoch']}", leave=False))
            bar[-1].set_postfix(loss=f"{e['loss']:.4f}", mse=f"{e['mse']:.5f}")
            bar[-1].update(1)
        elif e["event"] == "epoch":
            if bar:
                bar.pop().close()
            print(_epoch_line(e), file=sys.stderr)

    best = train(cfg, report)
    if best:
        print(f"best epoch {best['epoch']}: {args.out}", file=sys.stderr)
    return 0


def check_outputs(args: argparse.Namespace) -> None:
    """--out (and the resumable MODEL.last.npz beside it) checked now with the -o policy,
    not after the training (a take of --data is protected as every input is).
    A run may replace the files it writes even when it resumes from one of them
    (``--resume X.last.npz``, or fine-tuning X in place), atomically as always."""
    from pathlib import Path

    from faceclean.io import atomic, paths

    out = Path(args.out)
    last = None if args.arch in ("fc", "gbt") else out.with_name(out.stem + ".last.npz")
    atomic.check_writable(out, last)
    for p in (out, last):
        if p is not None:
            paths.rewritable(p)


def _report(args: argparse.Namespace) -> str:
    """``--report MODEL``: a model file of any kind, or a shipped model's name ('default',
    'lstm', 'fc', 'gbt'). The LSTM runs in torch (its training's own validation); every
    other kind through the runtime that cleans with it."""
    from faceclean.animation import Animation
    from faceclean.channels import ARKIT52
    from faceclean.datasets import dataset
    from faceclean.evaluation import harness
    from faceclean.learned import formats
    from faceclean.neural import checkpoint
    from faceclean.neural.validate import evaluate, measure, table
    from faceclean.resolve import model_file, resolve

    path = model_file(args.report)
    method = formats.method_of(path)  # one line for a file that is not a model
    takes = dataset.load_takes(args.data)
    _, val = dataset.holdout(takes, args.val_sources or (), args.seed)
    streams = harness.streams(val, list(harness.CONDITIONS))
    if method == "lstm":
        results = evaluate(checkpoint.load(path), streams, lag=True)
    else:
        cleaner = resolve(str(path)).build(ARKIT52)
        noisy = [Animation(s.noisy.times, s.noisy.arkit()[0], ARKIT52) for s in streams]
        outputs = harness.run_streams(cleaner, noisy)  # (N_i, 52) each
        results = measure(outputs, streams, ARKIT52, lag=True)
    names = sorted({t.source for t in val})
    what = f"{args.report} ({method}, {path.name})" if path.name != args.report else args.report
    return f"{what} on {', '.join(names)} ({len(val)} takes)\n\n{table(results)}"


def _adaptive(args: argparse.Namespace) -> int:
    """``--arch adaptive``: train or fine-tune the adaptive cleaner (neural/adaptive.py)."""
    from faceclean.errors import FacecleanError
    from faceclean.neural.adaptive import AdaptiveConfig, train

    if args.resume == "default":
        from faceclean.settings import MODELS

        args.resume = str(MODELS / "default.npz")
    cfg = AdaptiveConfig(out=args.out, data=args.data, val_sources=tuple(args.val_sources),
                         seed=args.seed, batch=args.batch, patience=args.patience,
                         resume=args.resume, max_batches=args.max_batches,
                         threads=args.threads)  # fmt: skip
    for key in ("epochs", "hidden", "lr"):
        if getattr(args, key) is not None:
            setattr(cfg, key, getattr(args, key))
    if args.synthetic_minutes:
        cfg.synthetic_minutes = args.synthetic_minutes
    if cfg.epochs < 1 or cfg.batch < 1:
        raise FacecleanError("--epochs and --batch must be at least 1")

    def report(e: dict) -> None:
        if e["event"] == "start":
            bar = e["start_score"]
            print(f"train on {', '.join(e['train_sources'])}; validate on "
                  f"{', '.join(e['val_sources']) or '-'}; the bar to beat: "
                  f"{bar:.3f}x raw ({'the starting model' if cfg.resume else 'tuned One Euro'})",
                  file=sys.stderr)  # fmt: skip
        elif e["event"] == "epoch":
            print(f"epoch {e['epoch']:3d} | train {e['train_loss']:.5f} | validation "
                  f"{e['score']:.3f}x raw | {e['seconds']:.0f}s" + (" *" if e["improved"] else ""),
                  file=sys.stderr)  # fmt: skip
        elif e["event"] == "stop" and e.get("note"):
            print(f"{e['note']}: {args.out} is the starting model", file=sys.stderr)

    best = train(cfg, report)
    print(f"best: {args.out} ({best['score']:.3f}x raw on validation)", file=sys.stderr)
    return 0


def _baseline(args: argparse.Namespace) -> int:
    """``--arch fc|gbt``: train a baseline (faceclean.neural.baselines)."""
    from faceclean.neural import baselines

    facts = baselines.train(
        args.arch, args.out, data=args.data, val_sources=args.val_sources, seed=args.seed,
        progress=lambda msg: print(msg, file=sys.stderr),
    )  # fmt: skip
    print(f"{args.arch}: {facts['frames']} frames, {facts['seconds']} s: {args.out}")
    return 0


def _epoch_line(e: dict) -> str:
    parts = [f"epoch {e['epoch']:3d}", f"train {e['train_loss']:.4f}"]
    for cond, v in (e.get("val") or {}).items():
        parts.append(
            f"{cond}: loss {v['loss']:.4f} mse {v['mse']:.5f} ({v['mse_ratio']:.2f}x raw) "
            f"jitter {v['jitter_ratio']:.2f} blink {_f(v['blink_closure'])}"
        )
    parts.append(f"{e['seconds']:.0f}s" + (" *" if e["improved"] else ""))
    return " | ".join(parts)


def _f(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.2f}"
