"""The FMUs themselves: valid, described as their blocks, equal to their blocks, robust in a process.

Every FMU is built once (cached in the project's FMU cache, rebuilt only when a source changes) and
then checked with fmpy, an importer that knows nothing of this project: the model description is
valid and says what the block's ports and parameters say, fmpy's own simulation gives the numbers
the block gives in-process, parameters set through FMI reach the block, a block's exception comes
back through the master as a `RunError`, and an FMU can be instantiated again and again in one
process (pythonfmu 0.7.0 once crashed the second time).
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from hoh_cosim.control.block import make_block
from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.scenario import ComponentSpec, Scenario
from hoh_cosim.errors import RunError
from hoh_cosim.fmi.build import ensure_fmus, fmu_name
from hoh_cosim.fmi.docs import fmus_readme
from hoh_cosim.fmi.model_description import finish_model_description
from hoh_cosim.fmi.slave import block_interface, port_element_names
from hoh_cosim.kinds import KINDS, ComponentKind
from hoh_cosim.params import leaves, with_values
from plant_models.operator import Operator, OperatorParams

ROOT = Path(__file__).resolve().parents[2]
KIND_NAMES = list(KINDS)
FMI_TYPE = {"real": "Real", "integer": "Integer", "boolean": "Boolean", "string": "String"}
STOP_S = 0.05
DT_S = 0.001


@pytest.fixture(scope="module")
def fmus() -> dict[str, Path]:
    """Every FMU, built once into the default cache (reused between runs while sources agree)."""
    return ensure_fmus(list(KINDS))


def _elements(ports: tuple[Any, ...]) -> list[tuple[str, str]]:
    """(variable name, unit) of every element of `ports`, in port order."""
    return [
        (name, unit)
        for port in ports
        for name, unit in zip(port_element_names(port.name, port.size), port.units, strict=True)
    ]


# --- 1. validation -------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", KIND_NAMES)
def test_fmu_passes_fmpy_validation(fmus: dict[str, Path], kind: str) -> None:
    assert validate_fmu(str(fmus[kind])) == []


# --- 2. the model description says what the block says ------------------------------------------


@pytest.mark.parametrize("kind", KIND_NAMES)
def test_model_description_matches_block(fmus: dict[str, Path], kind: str) -> None:
    spec = KINDS[kind]
    md = read_model_description(str(fmus[kind]))
    assert md.coSimulation is not None
    assert md.coSimulation.modelIdentifier == fmu_name(kind)
    by_name = {v.name: v for v in md.modelVariables}

    inputs = _elements(spec.block.inputs)
    outputs = _elements(spec.block.outputs)
    assert [v.name for v in md.modelVariables if v.causality == "input"] == [n for n, _ in inputs]
    assert [v.name for v in md.modelVariables if v.causality == "output"] == [n for n, _ in outputs]
    # ModelStructure: every output, in order, in Outputs and InitialUnknowns
    assert [u.variable.name for u in md.outputs] == [n for n, _ in outputs]
    assert [u.variable.name for u in md.initialUnknowns] == [n for n, _ in outputs]
    for name, unit in inputs + outputs:
        variable = by_name[name]
        assert variable.type == "Real", name
        assert variable.unit == unit, f"{name}: unit {variable.unit!r}, the port says {unit!r}"
    declared = {u.name for u in md.unitDefinitions}
    used = {v.unit for v in md.modelVariables if v.unit is not None}
    assert used <= declared, f"units used but not defined: {sorted(used - declared)}"

    assert md.defaultExperiment is not None
    assert md.defaultExperiment.stepSize is not None
    assert float(md.defaultExperiment.stepSize) > 0.0

    # parameters: every leaf of the parameter class, tunable exactly where the class says
    expected = {leaf.name: leaf for leaf in leaves(spec.params())}
    parameters = {v.name: v for v in md.modelVariables if v.causality == "parameter"}
    assert set(parameters) - {"seed"} == set(expected)
    assert ("seed" in parameters) == spec.random
    for name, leaf in expected.items():
        variable = parameters[name]
        assert variable.type == FMI_TYPE[leaf.kind], name
        assert variable.variability == ("tunable" if leaf.tunable else "fixed"), name
        if leaf.kind == "real":
            assert variable.unit == leaf.unit, name
            # pythonfmu writes starts with 16 significant digits: the last bit may differ
            assert float(variable.start) == pytest.approx(leaf.value, rel=1e-15, abs=0.0), name
        elif leaf.kind == "boolean":
            assert str(variable.start).lower() == str(leaf.value).lower(), name


@pytest.mark.parametrize("kind", ["ft150", "fse103", "loadcell", "operator", "breathing"])
def test_random_block_has_integer_seed(fmus: dict[str, Path], kind: str) -> None:
    assert KINDS[kind].random
    md = read_model_description(str(fmus[kind]))
    seed = next(v for v in md.modelVariables if v.name == "seed")
    assert (seed.type, seed.causality, seed.variability) == ("Integer", "parameter", "fixed")


def test_deterministic_blocks_have_no_seed(fmus: dict[str, Path]) -> None:
    for kind in ("plant", "estimator", "controller", "sequencer", "freehand"):
        md = read_model_description(str(fmus[kind]))
        assert "seed" not in {v.name for v in md.modelVariables}, kind


# --- 3. fmpy's own simulation equals the block stepped in-process --------------------------------

IDENTITY = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]


def _port(name: str, values: list[float]) -> dict[str, float]:
    return dict(zip(port_element_names(name, len(values)), values, strict=True))


# constant inputs (and a seed) per kind: something non-zero to work with, a valid rotation
START_VALUES: dict[str, dict[str, Any]] = {
    "operator": {
        **_port("p_BT_B", [0.4, -0.1, 0.3]),
        **_port("twist_B", [0.01, 0.0, -0.02, 0.0, 0.0, 0.1]),
        **_port("F_contact_B", [0.0, 0.0, 1.5]),
    },
    "plant": {
        **_port("F_hand_B", [2.0, -1.0, 0.5]),
        **_port("twist_cmd_B", [0.01, 0.0, 0.0, 0.0, 0.0, 0.0]),
    },
    "ft150": {"seed": 5, **_port("wrench_S_true", [1.0, -2.0, 3.0, 0.1, -0.2, 0.3])},
    "fse103": {"seed": 11, **_port("force_P_true", [0.5, -0.2, 4.0])},
    # a compression of 8 N along the cell's axis (-z_L), with a side load the cell must not see
    "loadcell": {"seed": 13, **_port("force_P_true", [1.5, -0.7, -8.0])},
    "estimator": {
        **_port("wrench_S", [1.0, -2.0, 3.0, 0.1, -0.2, 0.3]),
        **_port("force_P", [0.5, -0.2, 4.0]),
        **_port("R_BS", IDENTITY),
    },
    "controller": {
        **_port("F_hand_B", [3.0, 0.0, -1.0]),
        **_port("ready", [1.0]),
        **_port("p_BT_B", [0.4, -0.1, 0.3]),
    },
    "sequencer": {**_port("p_BT_B", [0.4, -0.1, 0.3]), **_port("R_BT", IDENTITY)},
    "panda": _port("tau_cmd", [1.0, -0.5, 0.2, 0.4, 0.1, -0.1, 0.05]),
    "impedance": {
        "task.approach_start_s": 0.0,
        "task.slide_start_s": 0.0,
        **_port("qd", [0.01] * 7),
        **_port("B", np.eye(7).reshape(49).tolist()),
        **_port("J", np.eye(6, 7).reshape(42).tolist()),
        **_port("p_BT_B", [0.3, 0.0, 0.4]),
        **_port("R_BT", IDENTITY),
    },
    "ur5_impedance": {
        "task.approach_start_s": 0.0,
        **_port("p_BT_B", [0.4, -0.1, 0.3]),
        **_port("R_BT", IDENTITY),
        **_port("F_ext_B", [0.0, 0.0, 2.0]),
        **_port("ready", [1.0]),
    },
    "breathing": {"seed": 3, "rate_per_min": 20.0},
    "freehand": {
        **_port("F_hand_B", [0.5, -0.2, 4.0]),
        **_port("hand_on", [1.0]),
        **_port("surface_offset_m", [0.002]),
    },
}


def _in_process(kind: str, start_values: dict[str, Any], n_steps: int) -> np.ndarray:
    """The block stepped in-process as fmpy steps the FMU: (n_steps + 1, outputs) rows, row 0 the
    outputs after initialisation (the block's initial outputs, or zeros)."""
    spec = KINDS[kind]
    params = spec.params()
    names = {leaf.name for leaf in leaves(params)}
    params = with_values(params, {k: v for k, v in start_values.items() if k in names})
    block: Any = make_block(spec.block, params, int(start_values.get("seed", 0)))
    inputs = {
        port.name: np.array(
            [float(start_values.get(n, 0.0)) for n in port_element_names(port.name, port.size)]
        )
        for port in spec.block.inputs
    }
    initial = getattr(block, "initial_outputs", None)
    outs = initial() if initial is not None else None
    rows = []

    def record(outputs: dict[str, np.ndarray] | None) -> None:
        rows.append(
            np.concatenate(
                [
                    np.zeros(p.size) if outputs is None else np.asarray(outputs[p.name], float)
                    for p in spec.block.outputs
                ]
            )
        )

    record(outs)
    for k in range(n_steps):
        # fmpy's communication points are start + n * interval, the step their difference
        t, t_next = k * DT_S, (k + 1) * DT_S
        record(block.step(t, t_next - t, inputs))
    return np.array(rows)


@pytest.mark.parametrize("kind", KIND_NAMES)
def test_fmpy_simulation_equals_block_in_process(fmus: dict[str, Path], kind: str) -> None:
    spec = KINDS[kind]
    start_values = START_VALUES[kind]
    result = simulate_fmu(
        str(fmus[kind]),
        stop_time=STOP_S,
        step_size=DT_S,
        output_interval=DT_S,
        start_values=start_values,
    )
    names = [n for n, _ in _elements(spec.block.outputs)]
    assert list(result.dtype.names) == ["time", *names]
    n_steps = round(STOP_S / DT_S)
    assert len(result) == n_steps + 1
    np.testing.assert_allclose(result["time"], np.arange(n_steps + 1) * DT_S, atol=1e-12)
    fmu_values = np.column_stack([result[n] for n in names])
    assert np.all(np.isfinite(fmu_values))

    expected = _in_process(kind, start_values, n_steps)
    np.testing.assert_allclose(fmu_values[-1], expected[-1], rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(fmu_values, expected, rtol=0.0, atol=1e-9)


def test_operator_and_ft150_outputs_move(fmus: dict[str, Path]) -> None:
    """The equality above is not two zeros agreeing: the operator pushes, the FT-150 delivers."""
    operator = _in_process("operator", START_VALUES["operator"], 50)
    assert operator[-1, 9] == 1.0  # hand_on (after F_hand_B, tau_hand_B, p_ref_B)
    assert np.linalg.norm(operator[-1, :3]) > 0.1  # F_hand_B
    ft150 = _in_process("ft150", START_VALUES["ft150"], 50)
    assert ft150[-1, -1] >= 5.0  # packets delivered
    assert not np.allclose(ft150[-1, :6], 0.0)
    other_seed = _in_process("ft150", {**START_VALUES["ft150"], "seed": 6}, 50)
    assert not np.allclose(ft150[-1, :6], other_seed[-1, :6])  # the seed matters


# --- 4. many instantiations in one process -------------------------------------------------------

_REPEAT = """
import sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from hoh_cosim.fmi import exit_fix

exit_fix.install()  # fmpy's freeInstance() unloads the library: release pythonfmu's state first

path = sys.argv[1]
md = read_model_description(path)
directory = extract(path)
outputs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
for i in range(20):
    fmu = FMU2Slave(
        guid=md.guid,
        unzipDirectory=directory,
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName=f"instance{i}",
    )
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    for k in range(3):
        fmu.doStep(k * 0.001, 0.001)
    values = fmu.getReal(outputs)
    assert len(values) == len(outputs)
    fmu.terminate()
    fmu.freeInstance()
print("instantiated", i + 1, "times")
"""


def test_fmu_instantiated_twenty_times_in_one_process(fmus: dict[str, Path]) -> None:
    # in a child process: a crash (pythonfmu 0.7.0 freeing the entry script's namespace) must fail
    # this test, not kill pytest
    done = subprocess.run(
        [sys.executable, "-c", _REPEAT, str(fmus["estimator"])],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, (
        f"exit status {done.returncode} (negative: killed by a signal)\n{done.stderr[-2000:]}"
    )
    assert "instantiated 20 times" in done.stdout


# --- 5. a block's exception comes back through the master ----------------------------------------

_BOOM_MODULE = "hoh_test_boom_fmu"
_BOOM_SCRIPT = '''
"""A test FMU whose block raises once the time passes `fail_after_s`."""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hoh_cosim.control.block import Port
from hoh_cosim.fmi.slave import BlockSlave as Fmi2Slave
from hoh_cosim.fmi.slave import pin_namespace

pin_namespace(globals())


@dataclass(frozen=True)
class BoomParams:
    fail_after_s: float = 1.0

    UNITS: ClassVar[dict] = {"fail_after_s": "s"}


class BoomBlock:
    """Echoes its input, then raises."""

    inputs: ClassVar = (Port("u", 1, "1", "anything"),)
    outputs: ClassVar = (Port("y", 1, "1", "the input, until the failure"),)

    def __init__(self, params=None):
        self.params = params or BoomParams()

    def reset(self):
        pass

    def retune(self, params):
        self.params = params

    def step(self, t, dt, inputs):
        if t > self.params.fail_after_s:
            raise ValueError(f"boom at t = {t:.3f} s")
        return {"y": np.array([inputs["u"][0]])}


class HohBoom(Fmi2Slave):
    block = BoomBlock
    params = BoomParams
'''


def _build_boom_fmu(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Path, Any]:
    """The test FMU built as `hoh_cosim.fmi.build` builds the project's, and its module."""
    import importlib.util

    from pythonfmu.builder import FmuBuilder

    source = tmp_path / "src"
    source.mkdir()
    script = source / f"{_BOOM_MODULE}.py"
    script.write_text(textwrap.dedent(_BOOM_SCRIPT))
    monkeypatch.setattr(sys, "path", list(sys.path))  # the builder inserts the script's folder
    try:
        built = Path(FmuBuilder.build_FMU(script, dest=tmp_path / "built"))
    finally:
        sys.modules.pop(_BOOM_MODULE, None)
    module_spec = importlib.util.spec_from_file_location(f"{_BOOM_MODULE}_here", script)
    assert module_spec is not None
    assert module_spec.loader is not None
    module = importlib.util.module_from_spec(module_spec)
    module_spec.loader.exec_module(module)
    specs = block_interface(module.BoomBlock, module.BoomParams)
    fmu = tmp_path / "HohBoom.fmu"
    with zipfile.ZipFile(built) as src, zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = finish_model_description(data, specs, "a block that raises")
            dst.writestr(item, data)
    return fmu, module


def test_block_exception_reaches_the_master_as_run_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    fmu, module = _build_boom_fmu(tmp_path, monkeypatch)
    assert validate_fmu(str(fmu)) == []
    kind = ComponentKind("boom", module.BoomBlock, module.BoomParams, _BOOM_MODULE, "raises")
    component = ComponentSpec(
        "boomer", kind, 1, module.BoomParams(fail_after_s=0.0205), seed=0, fmu=fmu
    )
    scenario = Scenario(
        path=tmp_path / "boom.yaml",
        name="boom",
        description="a component that raises",
        duration_s=0.05,
        dt_s=DT_S,
        seed=0,
        metrics="none",
        components={"boomer": component},
        connections=(),
        input_defaults={("boomer", "u"): np.array([0.5])},
        events=(),
        record=("boomer.y",),
    )
    # the same scenario in-process runs into the same exception
    with pytest.raises(RunError, match=r"boom at t = 0\.021"):
        simulate(scenario, "inprocess", progress=False)
    with pytest.raises(RunError) as caught:
        simulate(scenario, "fmu", fmu_paths={}, progress=False)
    message = str(caught.value)
    assert "boomer" in message
    assert "boom" in message
    # the failure time shows that the scenario's `fail_after_s` reached the block in the FMU
    assert "boom at t = 0.021" in message, message


# --- 6. the generated README ---------------------------------------------------------------------


def test_fmus_readme_is_up_to_date() -> None:
    readme = ROOT / "fmus" / "README.md"
    assert readme.read_text(encoding="utf-8") == fmus_readme(), (
        "fmus/README.md is out of date: regenerate it with "
        "`python -m hoh_cosim.fmi.docs > fmus/README.md`"
    )


# --- 7. parameters through FMI --------------------------------------------------------------------


@contextmanager
def _slave(fmu: Path, directory: Path, name: str) -> Iterator[tuple[FMU2Slave, dict[str, int]]]:
    md = read_model_description(str(fmu))
    unzipped = extract(str(fmu), unzipdir=str(directory))
    slave = FMU2Slave(
        guid=md.guid,
        unzipDirectory=unzipped,
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName=name,
    )
    slave.instantiate()
    try:
        yield slave, {v.name: v.valueReference for v in md.modelVariables}
    finally:
        with suppress(Exception):  # an instance that failed may refuse to terminate
            slave.terminate()
        slave.freeInstance()


def _get(slave: FMU2Slave, vrs: dict[str, int], port: str, size: int) -> np.ndarray:
    return np.array(slave.getReal([vrs[n] for n in port_element_names(port, size)]))


def _set_port(slave: FMU2Slave, vrs: dict[str, int], port: str, values: list[float]) -> None:
    slave.setReal([vrs[n] for n in port_element_names(port, len(values))], values)


P_START = [0.4, -0.1, 0.3]


def _operator_in_process(params: OperatorParams, n_steps: int) -> dict[str, np.ndarray]:
    block = Operator(params)
    inputs = {"p_BT_B": np.array(P_START), "twist_B": np.zeros(6), "F_contact_B": np.zeros(3)}
    out: dict[str, np.ndarray] = {}
    for k in range(n_steps):
        out = block.step(k * DT_S, DT_S, inputs)
    return out


def test_parameter_set_before_initialisation_reaches_block(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    n_steps = 400  # past the circle's start: the reference has moved away from the origin
    with _slave(fmus["operator"], tmp_path / "operator", "operator") as (slave, vrs):
        slave.setReal([vrs["radius_m"]], [0.08])
        _set_port(slave, vrs, "p_BT_B", P_START)
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        for k in range(n_steps):
            slave.doStep(k * DT_S, DT_S)
        p_ref = _get(slave, vrs, "p_ref_B", 3)
    wide = _operator_in_process(OperatorParams(radius_m=0.08), n_steps)["p_ref_B"]
    default = _operator_in_process(OperatorParams(), n_steps)["p_ref_B"]
    assert np.linalg.norm(wide - default) > 1e-4  # the radius shows in p_ref_B by then
    np.testing.assert_allclose(p_ref, wide, rtol=0.0, atol=1e-12)
    # twice the radius: twice the offset from where the hand took the handle
    np.testing.assert_allclose(p_ref - P_START, 2.0 * (default - P_START), atol=1e-12)


def test_tunable_parameter_set_between_steps_takes_effect(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    with _slave(fmus["operator"], tmp_path / "operator", "operator") as (slave, vrs):
        _set_port(slave, vrs, "p_BT_B", P_START)
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        for k in range(10):
            slave.doStep(k * DT_S, DT_S)
        assert slave.getReal([vrs["hand_on"]]) == [1.0]
        slave.setBoolean([vrs["released"]], [True])
        assert slave.getBoolean([vrs["released"]]) == [True]
        slave.doStep(10 * DT_S, DT_S)
        assert slave.getReal([vrs["hand_on"]]) == [0.0]
        np.testing.assert_array_equal(_get(slave, vrs, "F_hand_B", 3), np.zeros(3))
        # and back: the hand takes the handle again
        slave.setBoolean([vrs["released"]], [False])
        slave.doStep(11 * DT_S, DT_S)
        assert slave.getReal([vrs["hand_on"]]) == [1.0]


def test_fixed_parameter_set_after_initialisation_fails_the_step(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    from fmpy.fmi1 import FMICallException

    with _slave(fmus["operator"], tmp_path / "operator", "operator") as (slave, vrs):
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        slave.doStep(0.0, DT_S)
        slave.setReal([vrs["radius_m"]], [0.08])
        with pytest.raises(FMICallException):
            slave.doStep(DT_S, DT_S)


def test_initial_outputs_are_valid_during_initialisation(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    """A block with initial outputs (the plant) has them readable before the first step."""
    plant = make_block(KINDS["plant"].block, KINDS["plant"].params(), 0)
    initial = plant.initial_outputs()  # type: ignore[attr-defined]
    with _slave(fmus["plant"], tmp_path / "plant", "plant") as (slave, vrs):
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        p = _get(slave, vrs, "p_BT_B", 3)
        slave.exitInitializationMode()
    np.testing.assert_allclose(p, initial["p_BT_B"], rtol=0.0, atol=1e-12)
    assert np.all(np.isfinite(p))
    assert np.linalg.norm(p) > 0.0
