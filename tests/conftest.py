"""Shared fixtures: a seeded random generator and deterministic property tests."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import settings

from hoh_cosim.fmi import exit_fix

# Tests load and unload our FMUs through fmpy directly too: see hoh_cosim.fmi.exit_fix.
exit_fix.install()

# Property tests explore the same examples on every run, so a red test is reproducible.
settings.register_profile("deterministic", derandomize=True, deadline=None, max_examples=200)
settings.load_profile("deterministic")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20260522)
