"""Fixtures every test package shares; plain helpers are in tests/helpers.py."""

from __future__ import annotations

import signal

import pytest

from faceclean.settings import MODELS, takes_dir

# The Ctrl-C tests send SIGINT to commands they start. A shell starts a background job with
# SIGINT ignored, and an ignored signal stays ignored across exec, so under `make test &`
# those commands would rightly ignore it. The tests play a foreground terminal: a handled
# SIGINT here is reset to the default in every child.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Modules holding a test marked realtime (a live take replayed at its own pace, the
    CPU mostly idle) run first, whole: their waiting overlaps the other worker's work
    instead of trailing the run (measured: the tail of a run was one worker waiting)."""
    first = {item.module for item in items if item.get_closest_marker("realtime")}
    items.sort(key=lambda item: item.module not in first)  # stable: the order within kept


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


@pytest.fixture(scope="module")
def browser():
    """A headless Chromium (tests/headless.py's pinned build and flags), one per module;
    a module that uses it skips itself where ``headless.browser_missing()`` says so."""
    from headless import BROWSER_ARGS, CHROMIUM
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=BROWSER_ARGS)
        yield b
        b.close()
