"""engine.portrait_cache: the folder the photo family's portraits are read from by default
(``make portraits`` fills it; ``faceclean pairs`` and benchmarks/guided_eval.py read it)."""

from __future__ import annotations

from faceclean.synthetic import engine


def test_the_cache_is_under_the_home_folder(monkeypatch, tmp_path):
    monkeypatch.setenv("HOME", str(tmp_path))
    assert engine.portrait_cache() == tmp_path / ".cache" / "faceclean" / "portraits"


def test_pairs_without_portraits_names_the_same_folder(monkeypatch, tmp_path, capsys):
    from faceclean.cli import main

    monkeypatch.setenv("HOME", str(tmp_path))
    take = tmp_path / "take.csv"
    take.write_text("time,jawOpen\n0,0\n1,0\n")
    code = main(["pairs", str(take), "--families", "painted,photo", "-o", str(tmp_path / "o")])
    assert code != 0
    assert f"no portraits in {engine.portrait_cache()}" in capsys.readouterr().err
    assert not engine.portrait_cache().exists()
