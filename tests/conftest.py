"""Shared fixtures: a seeded random generator, deterministic property tests, a check that
pytest-xdist keeps its groups, and the compiled kernels loaded once before the workers start."""

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


def pytest_configure(config: pytest.Config) -> None:
    """Refuse a run whose pytest-xdist would ignore the groups of tests/xdist_groups.py: with pytest
    9.2, pytest-xdist 3.8's `--dist loadgroup` no longer marks the grouped tests and spreads them like
    any other (pytest-xdist issue 1386), so that a module's expensive run is made on every worker and
    the real-time tests run two at a time. pyproject.toml keeps pytest below 9.2 for that."""
    if getattr(config.option, "dist", "no") != "loadgroup":
        return
    from importlib.metadata import version

    from packaging.version import Version

    if Version(pytest.__version__) >= Version("9.2") and Version(
        version("pytest-xdist")
    ) <= Version("3.8.0"):
        raise pytest.UsageError(
            f"pytest {pytest.__version__} with pytest-xdist {version('pytest-xdist')}: "
            "--dist loadgroup ignores the xdist_group marks (pytest-xdist issue 1386); "
            'install the test extra (pytest below 9.2): pip install ".[test]"'
        )


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile (on a fresh machine) or load the kernels of hoh_cosim.control.kernels and
    plant_models.kernels once, in the process that starts the workers: otherwise every worker
    compiles them at once at its first test (10-30 s each on a fresh machine, measured), and the
    real-time tests' worlds would wait for it. Later processes load them from the cache."""
    if hasattr(session.config, "workerinput"):
        return
    from hoh_cosim.control.kernels import warm_up
    from plant_models.plant import Plant

    warm_up()
    Plant()
