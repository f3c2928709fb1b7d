"""Our FMUs in hosts that know nothing of our scenarios: fmpy alone, the FMI checker of
fmu-manipulation-toolbox, communication steps from 0.1 to 50 ms, and the FMU state.

Each FMU is probed in a fresh process of its own (tests/fmu_probe.py), as a foreign host would load
it: nothing set but what the FMU's model description gives.
"""

from __future__ import annotations

import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fmpy import simulate_fmu

from hoh_cosim.control.block import variable_step
from hoh_cosim.fmi.build import ensure_fmus
from hoh_cosim.kinds import KINDS

# one worker runs this module (tests/xdist_groups.py): the probes run once
pytestmark = pytest.mark.xdist_group(__name__)

PROBE = Path(__file__).resolve().parents[1] / "fmu_probe.py"
VARIABLE = [k for k, spec in KINDS.items() if variable_step(spec.block)]
SAMPLED = [k for k in KINDS if k not in VARIABLE]
# what moves each block while its other inputs stay at their start values
DRIVE = {
    "plant": {"twist_cmd_B[1]": 0.05},
    "panda": {"tau_cmd[1]": 1.0},
    "ft150": {"wrench_S_true[1]": 3.0},
    "fse103": {"force_P_true[3]": 2.0},
    "freehand": {"F_hand_B[1]": 0.3, "hand_on": 1.0},
}


@pytest.fixture(scope="module")
def fmus() -> dict[str, Path]:
    return ensure_fmus(list(KINDS))


@pytest.fixture(scope="module")
def probes(fmus) -> dict[str, dict[str, Any]]:
    """Every FMU through every check of tests/fmu_probe.py, one process per FMU."""

    def probe(kind: str) -> dict[str, Any]:
        checks = "alone,refuse,state" + (",steps" if kind in VARIABLE else "")
        done = subprocess.run(
            [sys.executable, str(PROBE), str(fmus[kind]), checks, json.dumps(DRIVE.get(kind, {}))],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert done.returncode == 0, f"{kind}: {done.stderr[-2000:]}"
        return json.loads(done.stdout.strip().splitlines()[-1])

    with ThreadPoolExecutor(max_workers=4) as pool:
        return dict(zip(KINDS, pool.map(probe, KINDS), strict=True))


def _largest_difference(a: dict[str, float], b: dict[str, float], prefix: str = "") -> float:
    return max(abs(a[k] - b[k]) for k in a if k.startswith(prefix))


@pytest.mark.parametrize("kind", list(KINDS))
def test_each_fmu_runs_alone_to_its_stop_time_with_its_defaults(probes, kind):
    alone = probes[kind]["alone"]
    assert alone["end"] == pytest.approx(alone["stop_time"]), alone
    assert alone["finite"], alone
    assert not alone["messages"], alone


@pytest.mark.parametrize("kind", list(KINDS))
def test_each_fmu_passes_the_fmi_checker_of_fmu_manipulation_toolbox(fmus, kind):
    fmutool = Path(sys.executable).with_name("fmutool")
    done = subprocess.run(
        [str(fmutool), "-input", str(fmus[kind]), "-check"], capture_output=True, text=True
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    assert "compliant with FMI-2.0" in output, output
    assert "No semantic error" in output, output


@pytest.mark.parametrize("kind", VARIABLE)
def test_a_variable_step_fmu_gives_the_1_ms_result_for_any_step(probes, kind):
    finals = probes[kind]["steps"]["finals"]
    reference = finals["1.0"]["outputs"]
    assert all(f["completed"] for f in finals.values()), finals
    for step_ms, final in finals.items():
        outputs = final["outputs"]
        if kind == "panda" and float(step_ms) < 1.0:
            # the integrator's step is the communication step below 1 ms (semi-implicit Euler at
            # 0.1 instead of 0.5 ms): the difference is its truncation error over 1.2 s at ~1 m/s
            assert _largest_difference(outputs, reference, "p_BT_B") < 3e-4, step_ms
            assert _largest_difference(outputs, reference, "q[") < 3e-3, step_ms
        else:
            scale = max(1.0, max(abs(v) for v in reference.values()))
            assert _largest_difference(outputs, reference) < 1e-9 * scale, step_ms


def test_the_plant_moves_under_the_drive_as_the_step_check_assumes(probes):
    reference = probes["plant"]["steps"]["finals"]["1.0"]["outputs"]
    # 0.05 m/s along x for 1.2 s from x = -0.1 m, less the ramp and the delay: about 6 cm
    moved = reference["p_BT_B[1]"] - (-0.1)
    assert 0.04 < moved < 0.061, moved


@pytest.mark.parametrize("kind", SAMPLED)
def test_a_sampled_fmu_refuses_a_changed_step_and_says_why(probes, kind):
    refuse = probes[kind]["refuse"]
    assert refuse["variable"] is False
    assert refuse["first"] is True, refuse
    assert refuse["second"] is False, refuse
    assert any(
        "sampled block" in m and "0.001 s" in m and "0.002 s" in m for m in refuse["messages"]
    ), refuse


@pytest.mark.parametrize("kind", VARIABLE)
def test_a_variable_step_fmu_says_so(probes, kind):
    assert probes[kind]["refuse"]["variable"] is True
    assert probes[kind]["refuse"]["second"] is True


@pytest.mark.parametrize("kind", list(KINDS))
def test_the_fmu_state_round_trips_in_memory_and_serialised(probes, kind):
    state = probes[kind]["state"]
    assert state["flags"] == [True, True]
    assert not state["messages"], state["messages"][:3]
    assert state["bytes"] > 0
    assert state["again"] == state["first"]  # set back: the same 0.1 s again, to the bit
    assert state["restored"] == state["first"]  # and in another instance, from the bytes
    if kind in DRIVE or kind in ("operator", "estimator"):
        assert state["first"] != state["at_save"]  # the 0.1 s in between changed something


def test_model_structure_lists_the_parameters_that_move_an_initial_output(fmus):
    """The issue's example: the arm's start posture moves the initial TCP pose, so the initial
    p_BT_B depends on arm.q0[2] (and InitialUnknowns says so), while a block without initial
    outputs declares none."""
    root = ET.fromstring(_model_description(fmus["plant"]))
    variables = root.find("ModelVariables").findall("ScalarVariable")
    index = {v.get("name"): i for i, v in enumerate(variables, start=1)}
    unknowns = {
        u.get("index"): u.get("dependencies", "").split()
        for u in root.find("ModelStructure").find("InitialUnknowns")
    }
    assert str(index["arm.q0[2]"]) in unknowns[str(index["p_BT_B[1]"])]
    moved = simulate_fmu(
        str(fmus["plant"]), stop_time=0.001, output_interval=1e-3, start_values={"arm.q0[2]": 0.5}
    )
    still = simulate_fmu(str(fmus["plant"]), stop_time=0.001, output_interval=1e-3)
    assert not np.isclose(moved["p_BT_B[3]"][0], still["p_BT_B[3]"][0])

    controller = ET.fromstring(_model_description(fmus["controller"]))
    for unknown in controller.find("ModelStructure").find("InitialUnknowns"):
        assert unknown.get("dependencies") == ""


def test_the_fmu_files_are_readable_by_every_user_and_compressed(fmus):
    import zipfile

    for path in fmus.values():
        assert path.stat().st_mode & 0o777 == 0o644, path
        with zipfile.ZipFile(path) as archive:
            assert {i.compress_type for i in archive.infolist()} == {zipfile.ZIP_DEFLATED}


def _model_description(path: Path) -> bytes:
    import zipfile

    with zipfile.ZipFile(path) as archive:
        return archive.read("modelDescription.xml")
