"""numba's cache of kernels inside an unpacked FMU, keyed by their source's content (hoh_cosim.control
.jit): a host that unpacks the FMU into a new folder each time loads the kernels compiled by the
first, where numba alone compiled them again in every folder."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hoh_cosim.control.jit import HAVE_NUMBA, in_unpacked_fmu

KERNEL = """
from hoh_cosim.control.jit import njit


@njit(cache=True)
def twice(x):
    return 2.0 * x
"""


def _unpacked(folder: Path) -> Path:
    """A folder laid out as an unpacked FMU with one kernel module in its resources."""
    (folder / "resources").mkdir(parents=True)
    (folder / "modelDescription.xml").write_text("<fmiModelDescription/>\n")
    (folder / "resources" / "kernel_probe.py").write_text(KERNEL)
    return folder / "resources"


def _load(resources: Path, cache: Path) -> str:
    """Call the kernel in a fresh process; numba's cache messages."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "NUMBA_DEBUG_CACHE": "1"}
    env["PYTHONPATH"] = os.pathsep.join([str(resources), env.get("PYTHONPATH", "")])
    code = "import kernel_probe; assert kernel_probe.twice(2.0) == 4.0"
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_a_file_is_in_an_unpacked_fmu_only_under_resources_beside_its_description(tmp_path):
    resources = _unpacked(tmp_path / "fmu")
    assert in_unpacked_fmu(str(resources / "kernel_probe.py"))
    assert in_unpacked_fmu(str(resources / "pkg" / "deeper.py"))
    assert not in_unpacked_fmu(str(tmp_path / "fmu" / "other.py"))
    (tmp_path / "fmu" / "modelDescription.xml").unlink()
    assert not in_unpacked_fmu(str(resources / "kernel_probe.py"))


@pytest.mark.skipif(not HAVE_NUMBA, reason="the kernels are plain Python without numba")
def test_a_kernel_compiled_in_one_unpacked_fmu_is_loaded_in_another_folder(tmp_path):
    cache = tmp_path / "cache"
    first = _load(_unpacked(tmp_path / "one"), cache)
    assert "data saved" in first, first
    # nothing beside the unpacked sources, where the next folder would not look
    assert not list((tmp_path / "one").rglob("*.nbc"))
    shutil.rmtree(tmp_path / "one")  # as a host removes its temporary folder
    second = _load(_unpacked(tmp_path / "two"), cache)
    assert "data loaded" in second, second
    assert "data saved" not in second, second


@pytest.mark.skipif(not HAVE_NUMBA, reason="the kernels are plain Python without numba")
def test_a_changed_kernel_in_an_unpacked_fmu_is_compiled_again(tmp_path):
    cache = tmp_path / "cache"
    _load(_unpacked(tmp_path / "one"), cache)
    resources = _unpacked(tmp_path / "two")
    source = resources / "kernel_probe.py"
    source.write_text(source.read_text() + "\n# another build\n")
    assert "data saved" in _load(resources, cache)
