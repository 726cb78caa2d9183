"""Fixtures every test package shares; plain helpers are in tests/helpers.py."""

from __future__ import annotations

import pytest

from faceclean.settings import MODELS, takes_dir


@pytest.fixture(scope="session")
def takes_root():
    """../shared/data/arkit_takes, or skip: the tests that read real takes say so."""
    root = takes_dir()
    if root is None:
        pytest.skip("shared data folder (arkit_takes/) absent")
    return root


@pytest.fixture(scope="session")
def shipped_model():
    """The shipped default model file (models/default.npz)."""
    return MODELS / "default.npz"
