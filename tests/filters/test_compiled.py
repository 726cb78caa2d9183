"""The compiled runs of usual frames (filters/compiled.py) give ``clean``'s numbers bit for
bit, on takes with every kind of frame the time rules know, and are off until enabled."""

from __future__ import annotations

import numpy as np
import pytest

from faceclean.datasets.performer import perform
from faceclean.filters import compiled
from faceclean.filters.one_euro import OneEuro
from faceclean.resolve import resolve

pytest.importorskip("numba")


def hostile(seed: int):
    """A take with jitter, dropped frames, a NaN value, an absurd one, a duplicate time,
    a step back, a gap that restarts the filter and irregular steps."""
    rng = np.random.default_rng(seed)
    take = perform(6.0, seed, fps=60.0)
    v = take.values + rng.normal(0, 0.01, take.values.shape)
    t = take.times + rng.uniform(-0.003, 0.003, len(take.times))
    v[40] = np.nan  # a missing frame
    v[50, 3] = np.nan  # one bad value
    v[60, 7] = 1e9  # a glitch
    t[70] = t[69]  # a duplicate
    t[80] = t[79] - 0.01  # backwards
    t[200:] += 1.0  # a pause past max_gap
    return take.__class__(t, v, take.names)


@pytest.fixture
def on():
    assert compiled.enable()
    yield
    compiled.disable()


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize(
    "words",
    [
        "one-euro",
        "default",
        "one-euro min_cutoff=0.5",
        "ema",
        "ema tau=0.1",
        "kalman",
        "kalman q=50 r=0.05",
    ],  # fmt: skip
)
def test_a_compiled_run_gives_the_same_bits(on, seed, words):
    parts = words.split()
    take = hostile(seed)
    build = lambda: resolve(parts[0], parts[1:]).build(take.names)  # noqa: E731
    cleaner = build()
    assert cleaner._compiled() is not None
    fast = cleaner.clean(take).values
    compiled.disable()
    assert build()._compiled() is None
    slow = build().clean(take).values
    compiled.enable()
    np.testing.assert_array_equal(fast, slow)  # NaN where NaN, every other value equal
    assert np.isnan(fast[40]).all() and np.isfinite(fast[41:]).all()


def test_the_per_frame_ema_too(on):
    from faceclean.filters.ema import Ema

    take = hostile(3)
    fast = Ema(names=take.names, gamma=0.3).clean(take).values
    compiled.disable()
    np.testing.assert_array_equal(fast, Ema(names=take.names, gamma=0.3).clean(take).values)


def test_off_until_enabled_and_stepping_is_untouched(on):
    take = hostile(2)
    f = OneEuro(names=take.names, min_cutoff=2.0)
    whole = f.clean(take).values
    f.reset()
    stepped = np.array([f.step(v, t) for t, v in zip(take.times, take.values, strict=True)])
    keep = take.valid  # clean leaves a missing frame missing; step repeats the last output
    np.testing.assert_array_equal(whole[keep], stepped[keep])
    compiled.disable()
    assert not compiled.enabled() and OneEuro(names=take.names)._compiled() is None


def test_the_deadband_run_is_the_loops_numbers(on):
    """compiled.deadband is y[n] = m[n] - clip(m[n] - y[n-1], -band, band), bit for bit;
    None while off."""
    rng = np.random.default_rng(7)
    m = np.cumsum(rng.normal(0, 0.01, (500, 6)), axis=0)
    band = np.array([0.0, 0.005, 0.01, 0.02, 0.05, 0.1])
    want = m.copy()
    for i in range(1, len(m)):
        want[i] -= np.clip(m[i] - want[i - 1], -band, band)
    np.testing.assert_array_equal(compiled.deadband(m, band), want)
    assert not np.array_equal(want[:, 3], m[:, 3])  # the band holds
    compiled.disable()
    assert compiled.deadband(m, band) is None


# --- the whole-take path (issue 38) ------------------------------------------------------

_ONE_FILE = """
import sys
from faceclean.cli import main
rc = main(["clean", sys.argv[1], "-o", sys.argv[2]])
print(rc, "numba" in sys.modules)
"""


def _take_file(tmp_path, frames: int):
    from faceclean import Animation, save
    from faceclean.channels import ARKIT52

    rng = np.random.default_rng(0)
    path = tmp_path / f"take{frames}.npz"
    save(Animation(np.arange(frames) / 60.0, rng.random((frames, 52)), ARKIT52), path)
    return path


@pytest.mark.parametrize("frames", [1, 2_000])
def test_a_short_take_never_loads_numba(tmp_path, frames):
    """Its process start pays nothing for the compiled path: numba stays unimported."""
    import subprocess
    import sys

    src = _take_file(tmp_path, frames)
    done = subprocess.run([sys.executable, "-c", _ONE_FILE, str(src), str(tmp_path / "o.npz")],
                          capture_output=True, text=True, check=True)  # fmt: skip
    assert done.stdout.splitlines()[-1] == "0 False"


def test_a_long_take_turns_the_kernels_on_and_loads_only_its_own(monkeypatch):
    compiled.disable()
    take = hostile(4)
    assert not compiled.for_take(len(take.times))  # short: off, numba not asked
    assert not compiled.enabled()
    valid = int(take.valid.sum())
    monkeypatch.setattr(compiled, "WHOLE_TAKE_FRAMES", valid)
    try:
        y = OneEuro(names=take.names).clean(take).values
        assert compiled.enabled() and set(compiled._kernels) == {"one_euro"}
        compiled.disable()
        monkeypatch.setattr(compiled, "WHOLE_TAKE_FRAMES", valid + 1)
        np.testing.assert_array_equal(y, OneEuro(names=take.names).clean(take).values)
        assert not compiled.enabled()
    finally:
        compiled.disable()


def test_the_switch_keeps_numba_off_and_says_so(monkeypatch):
    compiled.disable()
    monkeypatch.setenv(compiled.OFF, "0")
    assert not compiled.enable() and not compiled.for_take(10**7)
    assert compiled.status().startswith("numpy (slower")
    monkeypatch.delenv(compiled.OFF)
    assert compiled.status().startswith("compiled from")
    assert compiled.status(frames=10).startswith("numpy steps")


def test_without_numba_the_status_says_numpy(monkeypatch):
    import importlib.metadata

    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", missing)
    assert "numba not installed" in compiled.status()


def test_info_and_bench_say_how_a_long_take_is_cleaned(tmp_path, capsys):
    from faceclean.cli import main
    from faceclean.evaluation.bench import machine

    assert main(["info", str(_take_file(tmp_path, 10))]) == 0
    line = [x for x in capsys.readouterr().out.splitlines() if x.startswith("cleaning")]
    assert line == [f"cleaning    {compiled.status(10)}"]
    assert machine()["whole_take"] == compiled.status()


def test_the_tracker_maps_affine_kernel_is_the_product(on):
    rng = np.random.default_rng(1)
    a, w, b, v, c = rng.random((70, 5)), rng.random((5, 3)), rng.random((70, 4)), \
        rng.random((4, 3)), rng.random(3)  # fmt: skip
    np.testing.assert_allclose(compiled.affine(c, (a, w), (b, v)), a @ w + b @ v + c,
                               rtol=1e-14, atol=0)  # fmt: skip


def test_the_map_pass_bands_as_the_band_kernel_and_survives_off_and_on_again(on):
    """``map_run``'s band is ``noise_band``'s (one per-frame helper, compiled in its
    place); turned off, the helpers are plain Python again, and on again the kernels
    compile against the new ones."""
    from faceclean.learned import band

    rng = np.random.default_rng(2)
    n, m = 300, 4
    p = np.clip(np.cumsum(rng.normal(0, 0.02, (n, m)), axis=0) + 0.5, -0.2, 1.2)
    u, x, h = rng.random((n, m)), rng.random((n, m)), rng.uniform(0.01, 0.03, n)
    c, zero, idx = rng.normal(0, 0.05, m), np.zeros(m), np.arange(m)
    floor = np.full(m, 0.01)

    def both():
        y0, st1 = np.full(m, 0.5), [np.full(m, 0.5), np.full(m, 0.5), np.zeros(m)]
        st2 = [v.copy() for v in st1]
        none = (
            np.zeros(0, np.intp),
            np.zeros(0, np.intp),
            np.zeros(0),
            np.zeros(0),
            0,
            np.zeros(0),
            np.zeros(0),
            0.04,
        )  # no lift
        got = compiled.map_run(p.copy(), u, u, x, h, c, (zero, idx, zero, idx), none,
                               (2, floor, 16.0, band.TAU, band.CAP), y0, st1)  # fmt: skip
        m_ = np.clip(p + c, 0.0, 1.0)
        want = compiled.noise_band(m_, h, y0, *st2, floor, 16.0, band.TAU, band.CAP)
        return got, want, st1, st2

    got, want, st1, st2 = both()
    np.testing.assert_array_equal(got, want)  # the same helper, the same bits
    for a, b in zip(st1, st2, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(got, np.clip(p + c, 0, 1))  # the band held something
    compiled.disable()
    assert not hasattr(compiled._band_frame, "py_func")  # plain Python while off
    assert compiled.enable()
    assert hasattr(compiled._band_frame, "py_func")
    np.testing.assert_array_equal(both()[0], got)


def test_compiles_says_which_takes_run_compiled(monkeypatch):
    """A short take: no, and numba stays unloaded; a long one: yes for a cleaner with a
    kernel, no for one without."""
    from faceclean.channels import ARKIT52
    from faceclean.filters.base import StreamCleaner

    class Hold(StreamCleaner):  # no compiled run
        names = ARKIT52

        def _start(self, x):
            return (x.copy(),)

        def _advance(self, state, x, dt):
            return state, state[0].copy()

    compiled.disable()
    f = OneEuro(names=ARKIT52)
    assert not f.compiles(compiled.WHOLE_TAKE_FRAMES - 1) and not compiled.enabled()
    try:
        assert f.compiles(compiled.WHOLE_TAKE_FRAMES) and compiled.enabled()
        assert not Hold().compiles(compiled.WHOLE_TAKE_FRAMES)
    finally:
        compiled.disable()


def test_a_compiled_clean_shows_no_progress_bar(monkeypatch, capsys):
    """clean_with_progress: a take long enough for a bar gets one stepped in numpy, none
    where its runs go compiled (some 2 million frames a second); the same numbers."""
    from faceclean.cli.clean_take import PROGRESS_FRAMES, clean_with_progress

    take = perform(PROGRESS_FRAMES / 60.0 + 10.0, 5, fps=60.0)
    build = lambda: OneEuro(names=take.names)  # noqa: E731
    compiled.disable()
    monkeypatch.setattr(compiled, "WHOLE_TAKE_FRAMES", 10**9)
    slow = clean_with_progress(build(), take).values
    assert "cleaning" in capsys.readouterr().err
    monkeypatch.setattr(compiled, "WHOLE_TAKE_FRAMES", 0)
    try:
        fast = clean_with_progress(build(), take).values
        assert compiled.enabled() and "cleaning" not in capsys.readouterr().err
    finally:
        compiled.disable()
    np.testing.assert_array_equal(fast, slow)
