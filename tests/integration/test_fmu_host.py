"""The exported FMUs in a host that never installed hoh-cosim: a real clean virtual environment.

One environment has only what the FMUs declare and fmpy; there every FMU of `circles` runs alone
with `fmpy.simulate_fmu`'s defaults and agrees with the same run in this environment. Another has
fmpy alone (and numpy, which fmpy needs): an FMU that needs scipy fails to instantiate with one
line naming scipy and the pip install, and fmpy's command exits non-zero; one that needs numpy
alone runs. Both environments are made once in the FMU cache and reused (pip takes the wheels
from its own cache).
"""

from __future__ import annotations

import contextlib
import io
import re
import subprocess
from pathlib import Path

import pytest

from hoh_cosim.cli import main
from hoh_cosim.fmi.build import default_cache_dir
from hoh_cosim.fmi.hostcheck import _importer, host_python

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.xdist_group(__name__)  # one export, one environment at a time


def _export(out: Path, *options: str) -> str:
    said = io.StringIO()
    with contextlib.redirect_stdout(said):
        status = main(["export", str(ROOT / "scenarios/circles.yaml"), "--out", str(out), *options])
    return said.getvalue() + f"\nexit {status}"


@pytest.fixture(scope="module", params=[2, 3], ids=["fmi2", "fmi3"])
def exported(request, tmp_path_factory) -> tuple[Path, str, int]:
    out = tmp_path_factory.mktemp("export") / "circles"
    fmi = request.param
    return out, _export(out, "--check", "--fmi", str(fmi)), fmi


def test_every_fmu_runs_alone_in_a_host_with_only_what_it_declares(exported):
    _, said, fmi = exported
    assert said.endswith("exit 0"), said
    rows = [line for line in said.splitlines() if line.startswith("fmpy ")]
    assert len(rows) == 6, said
    for row in rows:
        fields = row.split()
        assert fields[2] == f"{fmi}.0", row
        assert float(fields[3]) <= 1e-9, row  # the worst difference, relative to the peak
        assert fields[4] == "ok", row
        assert "ran to 1 s, 1001 samples" in row
    assert "6 of 6 FMUs ran alone in a host without hoh-cosim" in said


def test_an_fmu_tells_what_its_host_lacks_in_one_line(exported):
    out, _, _ = exported
    python = host_python([_importer()], default_cache_dir() / "hosts")
    fmpy_cli = "import sys; from fmpy.cli import main; sys.argv[0] = 'fmpy'; sys.exit(main())"
    done = subprocess.run(
        [str(python), "-c", fmpy_cli, "simulate", str(out / "fmus/HohEstimator.fmu")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode != 0
    first = done.stderr.splitlines()[0]
    assert re.fullmatch(
        r"HohEstimator: needs scipy, which the host's Python \(3\.\d+\.\d+, \S+\) lacks: "
        r"pip install 'scipy>=[0-9.]+'",
        first,
    ), done.stderr
    # the operator needs numpy alone, which fmpy brings
    done = subprocess.run(
        [str(python), "-c", fmpy_cli, "simulate", str(out / "fmus/HohOperator.fmu")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-1000:]


def test_the_exports_readme_starts_with_what_a_host_needs(exported):
    out, _, fmi = exported
    head = "\n".join((out / "README.md").read_text().splitlines()[:20])
    assert "numpy>=" in head
    assert "scipy>=" in head
    assert "--check" in head
    assert f"the FMI {fmi}.0 co-simulation FMUs" in (out / "README.md").read_text()


def test_an_fmi_version_other_than_2_or_3_is_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "x"
    status = main(["export", str(ROOT / "scenarios/circles.yaml"), "--out", str(out), "--fmi", "4"])
    assert status == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "--fmi: invalid choice: 4 (choose from 2, 3)" in err
    assert not out.exists()
