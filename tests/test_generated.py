"""Generated hostile cases (tests/generated.py) under a brief, fixed hypothesis profile:
a few seconds in ``make test``; ``faceclean fuzz --generated`` runs the same long."""

from __future__ import annotations

import pytest
from generated import CASES
from hypothesis import HealthCheck, given, settings

BRIEF = settings(
    max_examples=25,
    derandomize=True,  # the same cases every run
    deadline=None,
    database=None,
    suppress_health_check=list(HealthCheck),
)


@pytest.mark.parametrize("name", sorted(CASES))
def test_generated_cases_hold_the_policy(name):
    strategy, check = CASES[name]
    BRIEF(given(strategy)(check))()
