"""The suite's pytest-xdist groups: pyproject.toml runs it with `-n auto --dist loadgroup`.

The tests of one group run on one worker, one after the other; every other test goes to whichever
worker is free. A module whose module-scoped fixture is an expensive run (a report, a recording, a
Dask cluster) marks itself `pytest.mark.xdist_group(__name__)`, so that the run is made once and not
once on each worker. The real-time tests share `REAL_TIME`.
"""

from __future__ import annotations

import pytest

REAL_TIME = pytest.mark.xdist_group("real-time")
"""Sessions that keep wall-clock time against emulated devices (the rehearsal world, the UR
controller): one at a time, so that two of them never take each other's core. (They still share the
machine with the other worker, and must hold under that load.)"""
