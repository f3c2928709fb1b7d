"""The FMI 3.0 FMUs: valid, the FMI 2 FMUs' interface in FMI 3 terms, equal to their blocks, stepped
by our master.

Every kind is built once into a temporary folder with `hoh_cosim.fmi.build3` and then checked with
fmpy, an importer that knows nothing of this project: the model description validates and says
what the block and the FMI 2 build say, fmpy's own simulation gives the block's numbers, the
master steps a scenario through FMI 3 FMUs (alone, and beside FMI 2 ones in one process) to the
in-process run's values, and errors come back with the FMU's message, never a crashed process.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import textwrap
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from hoh_cosim.control.block import port_element_names, variable_step
from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.fmi3_runtime import Fmu3Runtime, fmi_version
from hoh_cosim.cosim.recording import Recording
from hoh_cosim.cosim.scenario import ComponentSpec, Scenario, load_scenario
from hoh_cosim.errors import RunError
from hoh_cosim.fmi.build import ensure_fmus, fmu_name
from hoh_cosim.fmi.build3 import build_fmu3, build_kind3, fmu3_module
from hoh_cosim.fmi.slave import block_interface
from hoh_cosim.fmi.slave3 import FMI3_TYPE, TIME
from hoh_cosim.kinds import KINDS, ComponentKind, input_starts
from tests.integration.test_fmus import DT_S, START_VALUES, STOP_S, _in_process

pytestmark = pytest.mark.xdist_group(__name__)  # the FMUs are built once, on one worker

ROOT = Path(__file__).resolve().parents[2]
KIND_NAMES = list(KINDS)
RIG = ["operator", "plant", "ft150", "fse103", "estimator", "controller"]


@pytest.fixture(scope="module")
def fmus3(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Every kind's FMI 3 FMU, named as the FMI 2 one."""
    folder = tmp_path_factory.mktemp("fmi3")
    paths = {}
    for kind in KIND_NAMES:
        paths[kind] = folder / f"{fmu_name(kind)}.fmu"
        build_kind3(kind, paths[kind])
    return paths


# --- 1. validation and the model description ----------------------------------------------------


@pytest.mark.parametrize("kind", KIND_NAMES)
def test_fmi3_fmu_passes_fmpy_validation(fmus3: dict[str, Path], kind: str) -> None:
    assert fmi_version(fmus3[kind]) == "3.0"
    assert validate_fmu(str(fmus3[kind])) == []


@pytest.mark.parametrize("kind", KIND_NAMES)
def test_model_description_is_the_fmi2_interface(fmus3: dict[str, Path], kind: str) -> None:
    """Variable for variable what `block_interface` gives the FMI 2 FMU (names, value references,
    types, causalities, variabilities, units, start values), then `time`."""
    spec = KINDS[kind]
    md = read_model_description(str(fmus3[kind]))
    assert md.fmiVersion == "3.0"
    assert md.coSimulation.modelIdentifier == fmu_name(kind)
    expected = block_interface(spec.block, spec.params, input_starts(kind))
    variables = list(md.modelVariables)
    assert [v.name for v in variables] == [s.name for s in expected] + [TIME]
    for vr, (variable, want) in enumerate(zip(variables, expected, strict=False)):
        assert variable.valueReference == vr, want.name
        assert variable.type == FMI3_TYPE[want.type], want.name
        assert (variable.causality, variable.variability) == (want.causality, want.variability)
        assert not variable.dimensions, want.name  # scalars, as the adapter's docstring explains
        if want.type == "Real":
            assert variable.unit == want.unit, want.name
        if want.causality == "input" or (want.type == "Real" and want.causality == "parameter"):
            assert float(variable.start) == want.start, want.name  # 17 digits: exact
    time = variables[-1]
    assert (time.type, time.causality, time.unit, time.start) == (
        "Float64",
        "independent",
        "s",
        None,
    )
    declared = {u.name for u in md.unitDefinitions}
    assert {v.unit for v in variables if v.unit is not None} <= declared

    outputs = [v for v in variables if v.causality == "output"]
    assert [u.variable for u in md.outputs] == outputs
    assert [u.variable for u in md.initialUnknowns] == outputs
    assert all(u.dependencies == [] for u in md.outputs)  # no direct feedthrough
    assert md.coSimulation.canHandleVariableCommunicationStepSize == variable_step(spec.block)
    assert md.coSimulation.canGetAndSetFMUstate  # fmpy spells it as FMI 2 does
    assert md.coSimulation.canSerializeFMUstate
    assert float(md.defaultExperiment.stepSize) == pytest.approx(0.001)

    seed = [v for v in variables if v.name == "seed"]
    if spec.random:
        assert [(v.type, v.causality, v.variability, v.start) for v in seed] == [
            ("Int32", "parameter", "fixed", "0")
        ]
    else:
        assert seed == []


# --- 2. fmpy's own simulation equals the block stepped in-process -------------------------------


@pytest.mark.parametrize("kind", KIND_NAMES)
def test_fmpy_simulation_of_fmi3_fmu_equals_block(fmus3: dict[str, Path], kind: str) -> None:
    """As tests/integration/test_fmus.py checks the FMI 2 FMUs: row 0 is the outputs after
    initialisation (a block's `initial_outputs`, else zeros), the seed and parameters reach it."""
    result = simulate_fmu(
        str(fmus3[kind]),
        stop_time=STOP_S,
        step_size=DT_S,
        output_interval=DT_S,
        start_values=START_VALUES[kind],
    )
    names = [
        name
        for port in KINDS[kind].block.outputs
        for name in port_element_names(port.name, port.size)
    ]
    assert list(result.dtype.names) == ["time", *names]
    values = np.column_stack([result[n] for n in names])
    expected = _in_process(kind, START_VALUES[kind], round(STOP_S / DT_S))
    np.testing.assert_allclose(values, expected, rtol=0.0, atol=1e-9)


def test_inputs_start_where_the_build_says(fmus3: dict[str, Path], tmp_path: Path) -> None:
    """An FMU run alone, its inputs never set, starts from the world at rest (`input_starts`)."""
    starts = input_starts("operator")
    assert "p_BT_B" in starts
    with _Instance(fmus3["operator"], tmp_path, []) as (fmu, vrs):
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        got = fmu.getFloat64([vrs[n] for n in port_element_names("p_BT_B", 3)])
    np.testing.assert_array_equal(got, starts["p_BT_B"])


class _Instance:
    """An FMI 3 FMU instantiated by fmpy without debug logging, its messages kept in `log`."""

    def __init__(self, fmu: Path, folder: Path, log: list[tuple[int, str]]) -> None:
        md = read_model_description(str(fmu))
        self.vrs = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU3Slave(
            guid=md.guid,
            # a folder of its own: extracting over a loaded library would change it under the
            # process
            unzipDirectory=extract(str(fmu), unzipdir=tempfile.mkdtemp(dir=folder)),
            modelIdentifier=md.coSimulation.modelIdentifier,
            instanceName=fmu.stem,
        )
        self.log = log

    def _logged(self, env: Any, status: int, category: bytes, message: bytes) -> None:
        self.log.append((status, message.decode()))

    def __enter__(self) -> tuple[FMU3Slave, dict[str, int]]:
        self.fmu.instantiate(loggingOn=False, logMessage=self._logged)
        return self.fmu, self.vrs

    def __exit__(self, *exc: object) -> None:
        self.fmu.terminate()
        self.fmu.fmi3FreeInstance(self.fmu.component)  # the library stays loaded (exit_fix)


def test_sampled_block_refuses_another_step_and_fixed_parameters(
    fmus3: dict[str, Path], tmp_path: Path
) -> None:
    """As the FMI 2 adapter: a block that is not variable_step takes its first step as its period,
    a fixed parameter cannot change after initialisation; each is an fmi3Discard whose reason
    reaches the importer's logger with debug logging off."""
    assert not variable_step(KINDS["estimator"].block)
    log: list[tuple[int, str]] = []
    with _Instance(fmus3["estimator"], tmp_path, log) as (fmu, vrs):
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, DT_S)
        with pytest.raises(Exception, match="status 2"):
            fmu.doStep(DT_S, 2 * DT_S)
    assert log[-1][0] == 3  # fmi3Error
    assert "sampled block: its sample period is its first step, 0.001 s" in log[-1][1]
    assert "got a step of 0.002 s" in log[-1][1]

    with _Instance(fmus3["estimator"], tmp_path, log) as (fmu, vrs):
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, DT_S)
        fmu.setInt32([vrs["butterworth.order"]], [3])
        with pytest.raises(Exception, match="status 2"):
            fmu.doStep(DT_S, DT_S)
    assert (
        "fixed parameters cannot change after initialisation: ['butterworth.order']" in (log[-1][1])
    )


def test_a_wrong_value_reference_is_an_error_not_a_crash(
    fmus3: dict[str, Path], tmp_path: Path
) -> None:
    """No exception leaves the adapter (pythonfmu3 would release the instance twice): a get of a
    value reference the FMU lacks gives NaN and logs why, setting `time` is refused, and the
    FMU is not stepped again."""
    log: list[tuple[int, str]] = []
    with _Instance(fmus3["plant"], tmp_path, log) as (fmu, vrs):
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        assert np.isnan(fmu.getFloat64([100_000])).all()
        assert log[-1] == (
            3,
            "fmi3GetFloat64: ValueError: no Float64 variable has value reference 100000",
        )
        fmu.setFloat64([vrs[TIME]], [1.0])
        assert f"no Float64 variable that may be set has value reference {vrs[TIME]}" in log[-1][1]
        with pytest.raises(Exception, match="status 2"):
            fmu.doStep(0.0, DT_S)
        assert log[-1][1].startswith("not stepped after an earlier error: fmi3GetFloat64")


def test_tunable_parameter_and_fmu_state(fmus3: dict[str, Path], tmp_path: Path) -> None:
    """A tunable Boolean set between steps reaches the block (the hand lets go); a state taken
    before, serialised and restored, runs the same steps to the same outputs."""
    hand_on = port_element_names("hand_on", 1)
    with _Instance(fmus3["operator"], tmp_path, []) as (fmu, vrs):
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        for k in range(10):
            fmu.doStep(k * DT_S, DT_S)
        state = fmu.getFMUState()
        saved = fmu.serializeFMUState(state)
        fmu.freeFMUState(state)
        outputs = [v for n, v in vrs.items() if n.startswith(("F_hand_B", "p_ref_B"))]
        runs = []
        for _ in range(2):
            assert fmu.getFloat64([vrs[n] for n in hand_on]) == [1.0]
            fmu.setBoolean([vrs["released"]], [True])
            for k in range(10, 20):
                fmu.doStep(k * DT_S, DT_S)
            assert fmu.getFloat64([vrs[n] for n in hand_on]) == [0.0]
            runs.append(fmu.getFloat64(outputs))
            restored = fmu.deserializeFMUState(saved)
            fmu.setFMUState(restored)
            fmu.freeFMUState(restored)
            fmu.setBoolean([vrs["released"]], [False])
        assert fmu.getFloat64([vrs[TIME]]) == [pytest.approx(10 * DT_S)]
    assert runs[0] == runs[1]


# --- 3. the master steps FMI 3 FMUs as it steps the blocks ---------------------------------------


def _events_scenario(tmp_path: Path) -> Scenario:
    """circles.yaml for 6 s (the rebias, the hand taking the handle and drawing) with a tunable
    Real of the controller and a tunable Boolean of the operator changed on the way."""
    path = tmp_path / "events.yaml"
    path.write_text(
        f"extends: {ROOT / 'scenarios' / 'circles.yaml'}\n"
        "name: events\n"
        "events:\n"
        '  - {at_s: 4.0, set: {"controller.translation.slope[1]": 0.02}}\n'
        "  - {at_s: 5.0, set: {operator.released: true}}\n"
    )
    return load_scenario(path, duration_s=6.0)


def _assert_same_signals(rec: Recording, reference: Recording) -> None:
    """Every signal within 1e-9 of its peak in the reference (zero where the peak is zero)."""
    assert rec.columns == reference.columns
    for signal, columns in reference.columns.items():
        peak = np.max(np.abs(reference.values[:, columns]))
        gap = np.max(np.abs(rec.values[:, columns] - reference.values[:, columns]))
        assert gap <= 1e-9 * peak, f"{signal}: {gap:.3g} off, peak {peak:.3g}"


@pytest.fixture(scope="module")
def in_process(tmp_path_factory: pytest.TempPathFactory) -> Recording:
    scenario = _events_scenario(tmp_path_factory.mktemp("events"))
    return simulate(scenario, "inprocess", progress=False)


def test_scenario_through_fmi3_fmus_equals_in_process(
    fmus3: dict[str, Path],
    in_process: Recording,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    stepped: list[str] = []
    initialize = Fmu3Runtime.initialize

    def counted(self: Fmu3Runtime) -> None:
        stepped.append(self.spec.name)
        initialize(self)

    monkeypatch.setattr(Fmu3Runtime, "initialize", counted)
    scenario = _events_scenario(tmp_path)
    rec = simulate(scenario, "fmu", fmu_paths={k: fmus3[k] for k in RIG}, progress=False)
    assert sorted(stepped) == sorted(RIG)  # every component by the FMI 3 runtime
    _assert_same_signals(rec, in_process)
    # the run did something: the hand drew, the controller moved the probe, the hand let go
    assert np.ptp(rec["plant.p_BT_B"][:, 0]) > 0.01
    hand_on = rec["operator.hand_on"][:, 0]
    assert hand_on[4900] == 1.0
    assert hand_on[-1] == 0.0


def test_fmi2_and_fmi3_fmus_of_one_kind_in_one_process(
    fmus3: dict[str, Path], in_process: Recording, tmp_path: Path
) -> None:
    """The estimator through FMI 2 beside the FMI 3 rest, after runs that loaded the FMI 3
    estimator: the two entry scripts' modules (hoh_estimator, hoh3_estimator) do not collide."""
    assert fmu3_module("estimator") != KINDS["estimator"].fmu_script
    scenario = _events_scenario(tmp_path)
    paths = {k: fmus3[k] for k in RIG}
    simulate(scenario, "fmu", fmu_paths=paths, progress=False)  # the FMI 3 estimator loaded
    paths["estimator"] = ensure_fmus(["estimator"])["estimator"]
    assert fmi_version(paths["estimator"]) == "2.0"
    rec = simulate(scenario, "fmu", fmu_paths=paths, progress=False)
    _assert_same_signals(rec, in_process)


# --- 4. errors: a block's exception, an entry script that cannot import --------------------------

_BOOM_MODULE = "hoh3_test_boom_block"
_BOOM_SOURCE = '''
"""A test block that echoes its input, then raises once the time passes `fail_after_s`."""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hoh_cosim.control.block import Port


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
'''


@pytest.fixture
def boom(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Path, Any]:
    """The test block's FMI 3 FMU, its module carried in resources/ (a project file), and the
    module."""
    import importlib

    source = tmp_path / "src" / f"{_BOOM_MODULE}.py"
    source.parent.mkdir()
    source.write_text(textwrap.dedent(_BOOM_SOURCE))
    monkeypatch.syspath_prepend(str(source.parent))
    monkeypatch.delitem(sys.modules, _BOOM_MODULE, raising=False)
    module = importlib.import_module(_BOOM_MODULE)
    fmu = tmp_path / "HohBoom.fmu"
    build_fmu3(
        "test_boom",
        fmu,
        module.BoomBlock,
        module.BoomParams,
        "a block that raises",
        project_files=[source],
        resources={"notes.txt": "carried as given\n"},
    )
    return fmu, module


def test_block_exception_reaches_the_master_as_run_error(
    boom: tuple[Path, Any], tmp_path: Path
) -> None:
    fmu, module = boom
    assert validate_fmu(str(fmu)) == []
    with zipfile.ZipFile(fmu) as archive:
        names = set(archive.namelist())
        assert archive.read("resources/notes.txt") == b"carried as given\n"
    assert {f"resources/{_BOOM_MODULE}.py", "resources/hoh3_test_boom.py"} <= names
    assert "resources/pythonfmu/fmi2slave.py" in names  # the interface's import, for a bare host
    kind = ComponentKind("boom", module.BoomBlock, module.BoomParams, "unused", "raises")
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
    with pytest.raises(RunError) as caught:
        simulate(scenario, "fmu", fmu_paths={}, progress=False)
    # which component and FMU, which call and when, and the block's own words: the scenario's
    # fail_after_s reached the block in the FMU
    assert str(caught.value) == (
        "boomer (HohBoom): fmi3DoStep at t = 0.021 s returned Discard: fmi3DoStep at t = "
        "0.021 s: ValueError: boom at t = 0.021 s"
    )


_INSTANTIATE = """
import sys
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave

path = sys.argv[1]
md = read_model_description(path)
fmu = FMU3Slave(
    guid=md.guid,
    unzipDirectory=extract(path),
    modelIdentifier=md.coSimulation.modelIdentifier,
    instanceName="broken",
)
try:
    fmu.instantiate(loggingOn=False)  # fmpy's own logger, which prints
except Exception as exc:
    print("fmpy:", exc)
print("the process lives on")
"""


def test_an_entry_script_that_cannot_import_fails_instantiation_not_the_process(
    boom: tuple[Path, Any], tmp_path: Path
) -> None:
    """pythonfmu3 crashes the host on an exception while it imports the entry script; ours keep it
    for `__init__`, whose exception is the fatal message of a failed instantiation, which reaches
    the importer's logger without debug logging."""
    fmu, _ = boom
    broken = tmp_path / "HohBoomBroken.fmu"
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(broken, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "resources/hoh3_test_boom.py":
                data = data.replace(f"from {_BOOM_MODULE} ".encode(), b"from hoh_no_such_module ")
            dst.writestr(item, data)
    done = subprocess.run(
        [sys.executable, "-c", _INSTANTIATE, str(broken)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "[FATAL]" in done.stdout
    assert (
        "HohBoom: cannot import its code: ModuleNotFoundError: No module named 'hoh_no_such_module'"
    ) in done.stdout
    assert "fmpy: Failed to instantiate FMU" in done.stdout
    assert "the process lives on" in done.stdout


def test_the_main_command_steps_fmi3_fmus_and_refuses_them_to_other_engines(tmp_path, capsys):
    from hoh_cosim.cli import main

    circles = str(ROOT / "scenarios/circles.yaml")
    out = tmp_path / "run"
    assert main([circles, "--fmi", "3", "--duration", "0.5", "--out", str(out), "--quiet"]) == 0
    assert (out / "summary.json").is_file()
    capsys.readouterr()
    assert main([circles, "--fmi", "3", "--engine", "ecos", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "hoh-cosim: --fmi 3: only --engine fmu steps FMUs of FMI 3.0, not ecos"
    assert not (tmp_path / "x").exists()
