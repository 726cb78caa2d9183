"""Property tests: every reader and every relay decoder, fed arbitrary and mutated real
bytes, gives a valid result or the policy's one refusal, never another exception.

Bounded for ``make test``; ``faceclean fuzz`` runs the same properties at scale."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faceclean.cli import main
from faceclean.evaluation import fuzz

EXAMPLES = {t: 80 for t in fuzz.TARGETS}
EXAMPLES.update({"vmc": 200, "livelink-udp": 200, "ifacialmocap": 200})  # cheap: no files
EXAMPLES.update({"page": 200, "pairs": 120})  # a few seconds each
SETTINGS = dict(
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def _strategy(target: str):
    """Arbitrary bytes, a seed as is, or a seed mutated by the library's own edits
    (``fuzz.mutated``, drawn from a hypothesis-chosen numpy seed); the page's messages and
    pair folders: the library's own structured edits (``fuzz.draw``)."""
    pool = fuzz.seeds(target)
    if target in fuzz.SURFACES:
        drawn = st.integers(0, 2**63 - 1).map(lambda k: fuzz.draw(np.random.default_rng(k), target))
        return st.one_of(drawn, st.binary(max_size=512), st.sampled_from(pool))
    edits = st.integers(0, 2**63 - 1).map(lambda k: fuzz.mutated(np.random.default_rng(k), pool))
    return st.one_of(st.binary(max_size=fuzz.MAX_BYTES), edits, st.sampled_from(pool))


def _property(target: str):
    """A test for one target, its own hypothesis settings and input strategy."""

    @settings(max_examples=EXAMPLES[target], **SETTINGS)
    @given(data=_strategy(target))
    def test(tmp_path_factory, data: bytes) -> None:
        check = fuzz.Checker(target, _folder(tmp_path_factory, target))
        check(data)  # True (valid) or False (refused); anything raised is a bug

    return test


_FOLDERS: dict[str, object] = {}


def _folder(factory, target: str):
    if target not in _FOLDERS:
        _FOLDERS[target] = factory.mktemp(f"fuzz-{target}")
    return _FOLDERS[target]


for _target in fuzz.TARGETS:
    globals()[f"test_fuzz_{_target.replace('-', '_')}"] = _property(_target)


@pytest.mark.parametrize("target", fuzz.TARGETS)
def test_seeds_are_accepted(tmp_path, target):
    """The real inputs the mutations start from pass the check as valid input."""
    check = fuzz.Checker(target, tmp_path)
    assert fuzz.seeds(target) and all(check(s) for s in fuzz.seeds(target))


def test_checker_reports_a_broken_property(tmp_path):
    """The harness catches what it is for: an exception that is not the policy's."""
    check = fuzz.Checker("livelink-udp", tmp_path)
    with pytest.raises(AssertionError):
        fuzz._check_frame(object())
    assert check(b"") is False  # an empty datagram: a counted rejection


def test_fuzz_command_counts_inputs(capsys):
    assert main(["fuzz", "--target", "ifacialmocap", "--examples", "50"]) == 0
    out = capsys.readouterr().out
    assert "ifacialmocap  tried       50" in out and "no failure" in out
    assert main(["fuzz", "--target", "csv", "--examples", "0"]) == 2


def test_the_mutation_fuzzer_is_seeded_and_edits_real_seeds():
    """The same seed gives the same inputs; most inputs differ from every seed."""
    rng1, rng2 = np.random.default_rng(7), np.random.default_rng(7)
    first = [fuzz.draw(rng1, "csv") for _ in range(50)]
    assert first == [fuzz.draw(rng2, "csv") for _ in range(50)]
    assert sum(x not in fuzz.seeds("csv") for x in first) > 25
    report = fuzz.run("vmc", examples=300, seed=1)
    assert report.tried == 300 == report.accepted + report.refused and not report.failure


def test_the_page_and_pairs_checks_catch_what_they_are_for(tmp_path, monkeypatch):
    """An answer with NaN, an internal error, or a refused change kept, fails the page
    check; a stray exception from the pairs reader fails the pairs check."""
    from faceclean.datasets import paired
    from faceclean.ui import session

    page = fuzz.Checker("page", tmp_path)
    message = b'{"type": "view", "seq": 1, "t0": 0, "t1": 0.5}'
    assert page(message) is True
    monkeypatch.setattr(session.Base, "on_uncalibrate", lambda self, c, m: c.send({"type": "x"}))
    assert page(b'{"type": "uncalibrate"}') is True
    monkeypatch.setattr(session.Base, "on_uncalibrate", lambda self, c, m: 1 / 0)
    with pytest.raises(AssertionError, match="internal error"):
        page(b'{"type": "uncalibrate"}')

    def changes_then_refuses(self, client, m):
        self.window = (0.0, 0.1)
        raise session.FacecleanError("no")

    monkeypatch.setattr(session.Base, "on_uncalibrate", changes_then_refuses)
    with pytest.raises(AssertionError, match="changed the state"):
        page(b'{"type": "uncalibrate"}')
    pairs = fuzz.Checker("pairs", tmp_path)
    assert pairs(fuzz.seeds("pairs")[0]) is True and pairs(b"") is False
    monkeypatch.setattr(paired, "usable", lambda p: [][0])
    with pytest.raises(IndexError):
        pairs(fuzz.seeds("pairs")[0])


def test_a_failing_input_is_shrunk_to_what_fails():
    data = fuzz.seeds("ifacialmocap")[0]
    assert fuzz.shrink(lambda d: b"=head" in d, data) == b"=head"
    assert len(fuzz.shrink(lambda d: len(d) > 3, data)) == 4  # budget: 400 tries
