"""Curve figures and the comparison they draw: input, truth, cleaned, compared methods."""

from __future__ import annotations

import io as pyio

import numpy as np
import pytest

from faceclean.animation import Animation
from faceclean.channels import INDEX
from faceclean.cli import main
from faceclean.errors import FacecleanError
from faceclean.evaluation import comparison
from faceclean.io import save
from faceclean.report import plot
from faceclean.resolve import resolve, split_spec

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _clip(seconds: float = 3.0, fps: float = 60.0, seed: int = 0) -> tuple[Animation, Animation]:
    """(noisy, clean): a blink and a jaw movement, plus jitter and one spike."""
    t = np.arange(int(seconds * fps)) / fps
    clean = np.zeros((len(t), 52))
    clean[:, INDEX["jawOpen"]] = 0.3 + 0.25 * np.sin(2 * np.pi * 0.7 * t)
    clean[:, INDEX["eyeBlinkLeft"]] = np.exp(-(((t - 1.5) / 0.06) ** 2))
    noisy = clean + np.random.default_rng(seed).normal(0, 0.02, clean.shape)
    noisy[len(t) // 3, INDEX["jawOpen"]] += 0.5  # an occlusion spike
    return Animation.from_arkit(t, noisy.clip(0, 1)), Animation.from_arkit(t, clean)


def test_truth_at_other_times_is_interpolated_onto_the_input_times():
    noisy, _ = _clip()
    t = np.arange(0, 3.5, 1 / 24)  # 24 fps truth, a linear ramp: interpolation is exact
    truth = Animation(t, np.outer(t, np.ones(2)), ("JawOpen", "eyeBlink_L"))
    comp = comparison.compare(noisy, truth, ["ema"])
    assert comp.truth.values.shape == noisy.values.shape
    assert np.allclose(comp.truth.channel("jawOpen"), noisy.times)
    assert np.allclose(comp.truth.channel("eyeBlinkLeft"), noisy.times)
    assert np.isnan(comp.truth.channel("mouthSmileLeft")).all()  # absent from the truth


def test_comparison_holds_the_main_method_first_and_measures_without_truth():
    noisy, clean = _clip()
    comp = comparison.compare(noisy, clean, ["one-euro", "ema:tau=0.05"])
    assert list(comp.outputs) == ["one-euro", "ema:tau=0.05"] and comp.main == "one-euro"
    rows = comparison.untruthed(comp)
    for m in rows.values():
        assert m["jitter_after"] < m["jitter_before"]  # both smooth the jitter
        assert m["spikes"] >= 1
    assert rows["one-euro"]["missing"] == 0


def test_method_specs_parse_parameters_and_refuse_nonsense():
    assert split_spec("one-euro:min_cutoff=1.5,beta=0.3") == (
        "one-euro",
        ["min_cutoff=1.5", "beta=0.3"],
    )
    with pytest.raises(FacecleanError):
        resolve("ema:tau")
    noisy, _ = _clip()
    with pytest.raises(FacecleanError, match="unknown method"):
        comparison.compare(noisy, None, ["no-such-cleaner"])


def test_figure_has_one_panel_per_channel_with_every_series():
    noisy, clean = _clip()
    comp = comparison.compare(noisy, clean, ["one-euro", "kalman"])
    fig = plot.figure(comp, ["eyeBlinkLeft", "JawOpen"])  # any spelling
    assert len(fig.axes) == 2
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels == ["input", "truth", "one-euro", "kalman"]
    assert fig.axes[-1].get_xlabel() == "time (s)"
    assert fig.axes[0].get_title(loc="left") == "eyeBlinkLeft"


def test_png_and_svg_are_written_with_the_right_number_of_axes(tmp_path):
    from matplotlib.image import imread

    noisy, clean = _clip()
    comp = comparison.compare(noisy, clean, ["one-euro"])
    png, svg = tmp_path / "fig.png", tmp_path / "fig.svg"
    plot.save_figure(comp, png, ["eyeBlinkLeft", "jawOpen", "mouthSmileLeft"])
    plot.save_figure(comp, svg, ["eyeBlinkLeft", "jawOpen"], start=1.0, end=2.0)
    assert png.read_bytes()[:8] == PNG_MAGIC
    image = imread(pyio.BytesIO(png.read_bytes()))
    assert image.shape[0] > image.shape[1] * 0.5 and image.std() > 0.05  # drawn, not blank
    text = svg.read_text()
    assert text.lstrip().startswith("<?xml") and "<svg" in text
    assert text.count('id="axes_') == 2
    assert not list(tmp_path.glob(".*.tmp"))  # atomic: no temporary left behind


def test_default_channels_are_the_most_changed():
    noisy, clean = _clip()
    comp = comparison.compare(noisy, clean, ["one-euro"])
    cols = plot.pick_channels(comp, None, count=2)
    assert sorted(noisy.names[j] for j in cols) == ["eyeBlinkLeft", "jawOpen"]


def test_bad_requests_are_one_line_errors(tmp_path):
    noisy, clean = _clip()
    comp = comparison.compare(noisy, clean, ["ema"])
    with pytest.raises(FacecleanError, match="no channel"):
        plot.figure(comp, ["eyebrowWiggle"])
    with pytest.raises(FacecleanError, match="empty time window"):
        plot.figure(comp, ["jawOpen"], start=2.0, end=1.0)
    with pytest.raises(FacecleanError, match=".png"):
        plot.save_figure(comp, tmp_path / "fig.jpg", ["jawOpen"])
    assert not (tmp_path / "fig.jpg").exists()


def test_cli_plot_from_files(tmp_path, capsys):
    noisy, clean = _clip()
    noisy_path, clean_path = tmp_path / "noisy.csv", tmp_path / "clean.csv"
    save(noisy, noisy_path, fmt="livelink")
    half_rate = Animation.from_arkit(clean.times[::2], clean.values[::2])
    save(half_rate, clean_path, fmt="csv")  # the truth at 30 fps, the input at 60
    out = tmp_path / "fig.png"
    args = [str(noisy_path), "--truth", str(clean_path), "--channels", "eyeBlinkLeft,jawOpen"]
    assert main(["plot", *args, "--compare", "ema", "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == PNG_MAGIC
    assert "wrote" in capsys.readouterr().out
    assert main(["plot", str(noisy_path), "--channels", "nope", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("faceclean: ") and err.count("\n") == 1
    # a channel named twice is one panel; a list past any take's channels is one line, at once
    twice = tmp_path / "twice.svg"
    assert main(["plot", str(noisy_path), "--channels", "jawOpen,jawOpen", "-o", str(twice)]) == 0
    assert twice.read_text().count('id="axes_') == 1
    many = ",".join(["jawOpen", "eyeBlinkLeft"] * 40 + [f"x{k}" for k in range(70)])
    assert main(["plot", str(noisy_path), "--channels", many, "-o", str(out)]) == 2
    assert "names 72 channels: a figure shows at most 61" in capsys.readouterr().err
    assert main(["plot", str(tmp_path / "absent.csv"), "-o", str(out)]) == 2
