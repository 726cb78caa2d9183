"""Generated hostile cases (tests/generated.py) under a brief, fixed hypothesis profile:
a few seconds in ``make test``. The long run: ``FACECLEAN_GENERATED_EXAMPLES=100000
pytest tests/test_generated.py`` (random, not the fixed cases, when N is set)."""

from __future__ import annotations

import os

import pytest
from generated import CASES
from hypothesis import HealthCheck, given, settings

LONG = os.environ.get("FACECLEAN_GENERATED_EXAMPLES")
BRIEF = settings(
    max_examples=int(LONG) if LONG else 25,
    derandomize=not LONG,  # the same cases every run, unless a long run asks for more
    deadline=None,
    database=None,
    suppress_health_check=list(HealthCheck),
)


@pytest.mark.parametrize("name", sorted(CASES))
def test_generated_cases_hold_the_policy(name):
    strategy, check = CASES[name]
    BRIEF(given(strategy)(check))()
