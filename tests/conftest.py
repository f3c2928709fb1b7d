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


_WARM_UP = (
    "from hoh_cosim.control.kernels import warm_up; from plant_models.plant import Plant; "
    "warm_up(); Plant()"
)
"""What compiles (on a fresh machine) or loads every kernel: the control core's, and the plant's
(plant_models.kernels: the eager ones at import, the UR5's kinematics at Plant())."""


def _installed_plant_models() -> str | None:
    """Where a process started outside this checkout imports plant_models from, if not from here.

    The suite imports the checkout's `plant_models` (the root is on its path, for `tests`), but the
    processes it starts from elsewhere (an FMU probe, a study's Dask worker, a `hoh-cosim` run)
    import the installed one: after `pip install .` (not `-e`) that is a second copy, whose numba
    cache is a second cache."""
    import importlib.machinery
    import os
    import sys
    from pathlib import Path

    import plant_models

    root = Path(__file__).resolve().parents[1]
    path = [p for p in sys.path if p and Path(p).resolve() != root and p != os.curdir]
    spec = importlib.machinery.PathFinder.find_spec("plant_models", path)
    if spec is None or spec.origin is None:
        return None
    here = Path(plant_models.__file__).resolve()
    return None if Path(spec.origin).resolve() == here else spec.origin


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile (on a fresh machine) or load the kernels of hoh_cosim.control.kernels and
    plant_models.kernels once, in the process that starts the workers: otherwise every worker
    compiles them at once at its first test (10-30 s each on a fresh machine, measured), and the
    real-time tests' worlds would wait for it. Later processes load them from the cache. Where the
    installed plant_models is another copy than the checkout's, a process started outside the
    checkout warms its cache at the same time: otherwise each FMU probe and study worker compiled
    the plant's kernels again (20 s for the plant's FMU on a fresh clone, measured)."""
    if hasattr(session.config, "workerinput"):
        return
    import subprocess
    import sys
    import tempfile

    from hoh_cosim.control.kernels import warm_up
    from plant_models.plant import Plant

    other = None
    if _installed_plant_models() is not None:
        other = subprocess.Popen([sys.executable, "-c", _WARM_UP], cwd=tempfile.gettempdir())
    warm_up()
    Plant()
    if other is not None and other.wait() != 0:
        raise pytest.UsageError("the installed plant_models' kernels failed to compile")
