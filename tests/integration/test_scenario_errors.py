"""Bad scenario files and bad command lines, as `hoh-cosim SCENARIO.yaml` meets them.

The contract (src/hoh_cosim/cli.py, src/hoh_cosim/cosim/scenario.py): a mistake in the input gets
exit status 2 and one line on stderr, `hoh-cosim: FILE: YAML.PATH: problem`, with no traceback, and
nothing is written that could pass for a result (no output directory, no summary.json).

Every bad scenario is scenarios/circles.yaml, read with yaml.safe_load, changed in one place and
written to tmp_path; each fails validation before anything runs (the engine is the in-process one,
so no FMU is built).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from hoh_cosim.cli import main
from hoh_cosim.control.controller import ControllerParams
from hoh_cosim.control.estimator import EstimatorParams
from hoh_cosim.cosim.scenario import load_scenario
from hoh_cosim.errors import ConfigError
from hoh_cosim.kinds import KINDS
from hoh_cosim.params import leaves

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"
CIRCLES = SCENARIOS / "circles.yaml"

# the documented top-level keys of a scenario file (scenario.py's docstring)
TOP_KEYS = (
    "extends",
    "name",
    "description",
    "duration_s",
    "dt_s",
    "seed",
    "metrics",
    "components",
    "connections",
    "inputs",
    "events",
    "record",
    "record_every",
)
CIRCLES_COMPONENTS = "operator, plant, ft150, fse103, estimator, controller"


@pytest.fixture(autouse=True)
def _in_tmp_path(tmp_path, monkeypatch):
    """Run in tmp_path: a default runs/<name>, or anything else written by mistake, lands there."""
    monkeypatch.chdir(tmp_path)


def circles() -> dict[str, Any]:
    return yaml.safe_load(CIRCLES.read_text(encoding="utf-8"))


def write_scenario(directory: Path, data: Any, name: str = "bad.yaml") -> Path:
    path = directory / name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def files_under(directory: Path) -> set[Path]:
    return {p.relative_to(directory) for p in directory.rglob("*")}


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """`main(argv)`'s exit status (argparse's usage errors raise SystemExit(2) instead of
    returning it, which the command line turns into the same status), stdout and stderr."""
    try:
        status = main(argv)
    except SystemExit as exc:
        status = exc.code  # type: ignore[assignment]
    out, err = capsys.readouterr()
    return status, out, err


def assert_one_line_rejection(status: int, out: str, err: str, prefix: str = "") -> None:
    assert status == 2, (status, err)
    assert "Traceback" not in err
    assert err.count("\n") == 1, err
    assert err.endswith("\n"), err
    assert err.startswith("hoh-cosim: "), err
    assert err.startswith(f"hoh-cosim: {prefix}"), err
    assert out == ""


# --- mutations of circles.yaml ---------------------------------------------------------------


def _node(data: Any, parts: list[str]) -> Any:
    for part in parts:
        data = data[int(part)] if isinstance(data, list) else data[part]
    return data


def put(path: str, value: Any) -> Callable[[dict], None]:
    """Set the value at a '/'-separated path (list indices as numbers)."""
    *parents, last = path.split("/")

    def mutate(data: dict) -> None:
        node = _node(data, parents)
        if isinstance(node, list):
            node[int(last)] = value
        else:
            node[last] = value

    return mutate


def drop(path: str) -> Callable[[dict], None]:
    """Remove the value at a '/'-separated path."""
    *parents, last = path.split("/")

    def mutate(data: dict) -> None:
        node = _node(data, parents)
        del node[int(last) if isinstance(node, list) else last]

    return mutate


def both(*mutations: Callable[[dict], None]) -> Callable[[dict], None]:
    def mutate(data: dict) -> None:
        for m in mutations:
            m(data)

    return mutate


def append_connection(src: str, dst: str) -> Callable[[dict], None]:
    return lambda data: data["connections"].append({"from": src, "to": dst})


def insert_connection(index: int, src: str, dst: str) -> Callable[[dict], None]:
    return lambda data: data["connections"].insert(index, {"from": src, "to": dst})


def events(*items: dict) -> Callable[[dict], None]:
    return put("events", list(items))


def _ports(kind: str, direction: str) -> str:
    block = KINDS[kind].block
    return ", ".join(p.name for p in (block.inputs if direction == "in" else block.outputs))


def _fields(params: type) -> str:
    return ", ".join(f.name for f in dataclasses.fields(params))


# (mutation, YAML path the message must start with, fragments the message must hold)
BAD_SCENARIOS = [
    # unknown names: the message lists what is known
    pytest.param(
        put("nope", 1),
        "nope",
        ["unknown key (expected one of: ", *TOP_KEYS],
        id="unknown-top-level-key",
    ),
    pytest.param(
        put("components/plant/nope", 1),
        "components.plant.nope",
        ["unknown key (expected one of: kind, every, params, fmu)"],
        id="unknown-key-in-component",
    ),
    pytest.param(  # a key with a carriage return (found by the fuzzer): still one line
        put("components/plant/\r\nx", 1),
        "components.plant.\\r\\nx",
        ["unknown key (expected one of: kind, every, params, fmu)"],
        id="unknown-key-with-a-line-break",
    ),
    pytest.param(
        put("components/plant/kind", "robot"),
        "components.plant.kind",
        [f"unknown component kind 'robot' (kinds: {', '.join(KINDS)})"],
        id="unknown-component-kind",
    ),
    pytest.param(
        put("components/robot", {}),
        "components.robot",
        [f"unknown component kind 'robot' (kinds: {', '.join(KINDS)})"],
        id="unknown-component-kind-from-name",
    ),
    pytest.param(
        put("components/estimator/params/nope", 1.0),
        "components.estimator.params.nope",
        [f"unknown parameter of EstimatorParams (one of: {_fields(EstimatorParams)})"],
        id="unknown-parameter",
    ),
    pytest.param(
        put("components/estimator/params/tool/nope", 1.0),
        "components.estimator.params.tool.nope",
        ["unknown parameter of ToolParams (one of: mass_kg, p_SC_S)"],
        id="unknown-nested-parameter",
    ),
    # wrong value types
    pytest.param(
        put("duration_s", "30"),
        "duration_s",
        ["expected a number, got '30'"],
        id="duration-is-a-string",
    ),
    pytest.param(
        put("dt_s", "fast"),
        "dt_s",
        ["expected a number, got 'fast'"],
        id="dt-is-a-string",
    ),
    pytest.param(
        put("seed", -1),
        "seed",
        ["expected an integer >= 0, got -1"],
        id="negative-seed",
    ),
    pytest.param(
        put("components/controller/every", 0),
        "components.controller.every",
        ["expected an integer >= 1, got 0"],
        id="every-zero",
    ),
    pytest.param(
        put("record_every", 0),
        "record_every",
        ["expected an integer >= 1, got 0"],
        id="record-every-zero",
    ),
    pytest.param(
        put("components/estimator/params/tool/p_SC_S", [-0.0125, -0.00033]),
        "components.estimator.params.tool.p_SC_S",
        ["expected a list of 3 numbers, got 2 values"],
        id="vector-of-wrong-length",
    ),
    pytest.param(
        put("components/estimator/params/tool/p_SC_S", [-0.0125, "x", -0.075]),
        "components.estimator.params.tool.p_SC_S[2]",
        ["expected a number, got 'x'"],
        id="vector-element-not-a-number",
    ),
    pytest.param(
        put("components/controller/params/contact_compensation", 1),
        "components.controller.params.contact_compensation",
        ["expected true or false, got 1"],
        id="boolean-given-a-number",
    ),
    pytest.param(
        put("components/estimator/params/probe_rebias_packets", 1.5),
        "components.estimator.params.probe_rebias_packets",
        ["expected an integer, got 1.5"],
        id="integer-given-a-fraction",
    ),
    pytest.param(
        put("components/plant/params/arm", 125.0),
        "components.plant.params.arm",
        ["expected a mapping of parameters, got 125.0"],
        id="parameter-group-given-a-number",
    ),
    pytest.param(
        put("components/operator/params/task", "square"),
        "components.operator.params.task",
        ["expected one of off, hold, circle", "got 'square'"],
        id="string-parameter-out-of-its-choices",
    ),
    pytest.param(
        put("components/estimator/params/tool/mass_kg", -1.0),
        "components.estimator.params.tool.mass_kg",
        ["-1.0"],
        id="parameter-out-of-range",
    ),
    pytest.param(
        put("components/plant/kind", ["plant"]),
        "components.plant.kind",
        ["unknown component kind ['plant']"],
        id="component-kind-is-a-list",
    ),
    # connections
    pytest.param(
        put("connections/3/to", "nobody.p_BT_B"),
        "connections[3].to",
        [f"unknown component 'nobody' (components: {CIRCLES_COMPONENTS})"],
        id="connection-unknown-component",
    ),
    pytest.param(
        put("connections/3/to", "operator.nope"),
        "connections[3].to",
        [f"unknown input port 'operator.nope' (inputs of operator: {_ports('operator', 'in')})"],
        id="connection-unknown-input-port",
    ),
    pytest.param(
        put("connections/3/from", "plant.F_hand_B"),
        "connections[3].from",
        [f"unknown output port 'plant.F_hand_B' (outputs of plant: {_ports('plant', 'out')})"],
        id="connection-from-an-input",
    ),
    pytest.param(
        put("connections/3/from", "plant p_BT_B"),
        "connections[3].from",
        ["expected 'component.port' or 'component.port[i]', got 'plant p_BT_B'"],
        id="connection-endpoint-syntax",
    ),
    pytest.param(
        both(
            drop("connections/8"), insert_connection(8, "ft150.wrench_S", "estimator.wrench_S[0]")
        ),
        "connections[8].to",
        ["unknown port 'estimator.wrench_S[0]' (wrench_S has elements 1 to 6)"],
        id="connection-element-zero",
    ),
    pytest.param(
        put("connections/3/from", "plant.twist_B"),
        "connections[3]",
        ["sizes differ: plant.twist_B has 6 values, operator.p_BT_B takes 3"],
        id="connection-size-mismatch",
    ),
    pytest.param(
        put("connections/3/from", "plant.penetration"),
        "connections[3]",
        ["sizes differ: plant.penetration has 1 values, operator.p_BT_B takes 3"],
        id="connection-scalar-into-vector",
    ),
    pytest.param(
        append_connection("plant.p_BT_B", "controller.p_BT_B"),
        "connections[25].to",
        ["controller.p_BT_B is already fed by connections[19]"],
        id="input-fed-twice",
    ),
    pytest.param(
        append_connection("plant.twist_B[1]", "plant.twist_cmd_B[6]"),
        "connections[25].to",
        ["plant.twist_cmd_B[6] is already fed by connections[2]"],
        id="input-element-fed-twice",
    ),
    pytest.param(
        drop("connections/3/from"),
        "connections[3].from",
        ["missing"],
        id="connection-without-from",
    ),
    pytest.param(
        drop("connections/3/to"),
        "connections[3].to",
        ["missing"],
        id="connection-without-to",
    ),
    pytest.param(
        put("connections/3/via", "cable"),
        "connections[3].via",
        ["unknown key (expected one of: from, to)"],
        id="connection-unknown-key",
    ),
    pytest.param(
        put("connections/2", "controller.twist_B -> plant.twist_cmd_B"),
        "connections[2]",
        ["expected a mapping"],
        id="connection-not-a-mapping",
    ),
    # inputs nothing feeds
    pytest.param(
        drop("connections/1"),
        "connections",
        ["input 'plant.tau_hand_B[1]' is not connected and has no value under 'inputs'"],
        id="input-left-unconnected",
    ),
    pytest.param(
        put("connections/0", {"from": "operator.F_hand_B[1]", "to": "plant.F_hand_B[1]"}),
        "connections",
        ["input 'plant.F_hand_B[2]' is not connected and has no value under 'inputs'"],
        id="input-element-left-unconnected",
    ),
    pytest.param(
        both(drop("connections/1"), put("inputs", {"plant.tau_hand_B": [0.0, 0.0]})),
        "inputs.plant.tau_hand_B",
        ["expected 3 values, got 2"],
        id="inputs-wrong-number-of-values",
    ),
    pytest.param(
        both(drop("connections/1"), put("inputs", {"plant.tau_hand_B": [0.0, 0.0, "x"]})),
        "inputs.plant.tau_hand_B",
        ["expected a number, got 'x'"],
        id="inputs-value-not-a-number",
    ),
    pytest.param(
        put("inputs", {"plant.p_BT_B": [0.0, 0.0, 0.0]}),
        "inputs.plant.p_BT_B",
        [f"unknown input port 'plant.p_BT_B' (inputs of plant: {_ports('plant', 'in')})"],
        id="inputs-for-an-output",
    ),
    pytest.param(
        # short, since today it runs
        both(put("inputs", {"plant.tau_hand_B": [0.0, 0.0, 0.0]}), put("duration_s", 0.05)),
        "inputs.plant.tau_hand_B",
        ["connections[1]"],
        id="input-both-connected-and-given-a-value",
    ),
    # events
    pytest.param(
        events({"at_s": 5.0, "set": {"estimator.tool.mass_kg": 0.5}}),
        "events[0].set.estimator.tool.mass_kg",
        ["estimator.tool.mass_kg cannot change during a run (not a tunable parameter)"],
        id="event-changes-a-fixed-parameter",
    ),
    pytest.param(
        events(
            {"at_s": 20.0, "set": {"controller.contact_compensation": False}},
            {"at_s": 5.0, "set": {"controller.use_probe": False}},
        ),
        "events[1].set.controller.use_probe",
        ["controller.use_probe cannot change during a run (not a tunable parameter)"],
        id="event-changes-a-fixed-parameter-second-in-file-first-in-time",
    ),
    pytest.param(
        events({"at_s": 31.0, "set": {"controller.contact_compensation": False}}),
        "events[0].at_s",
        ["expected a time within 0 to 30.0 s, got 31.0"],
        id="event-after-the-end",
    ),
    pytest.param(
        events({"at_s": -1.0, "set": {"controller.contact_compensation": False}}),
        "events[0].at_s",
        ["expected a time within 0 to 30.0 s, got -1.0"],
        id="event-before-the-start",
    ),
    pytest.param(
        events({"at_s": 5.0, "set": {"controller.contact_compensation": 1}}),
        "events[0].set.controller.contact_compensation",
        ["expected true or false, got 1"],
        id="event-wrong-type",
    ),
    pytest.param(
        events({"at_s": 5.0, "set": {"controller.nope": 1}}),
        "events[0].set.controller.nope",
        [f"unknown parameter of ControllerParams (one of: {_fields(ControllerParams)})"],
        id="event-unknown-parameter",
    ),
    pytest.param(
        events({"at_s": 5.0}),
        "events[0]",
        ["expected at_s and set"],
        id="event-without-set",
    ),
    pytest.param(
        events({"at_s": 5.0, "set": {"nobody.released": True}}),
        "events[0].set.nobody.released",
        [f"unknown component 'nobody' (components: {CIRCLES_COMPONENTS})"],
        id="event-unknown-component",
    ),
    pytest.param(
        events(
            {"at_s": "soon", "set": {"controller.contact_compensation": False}},
            {"at_s": 5.0, "set": {"controller.contact_compensation": True}},
        ),
        "events[0].at_s",
        ["expected a number, got 'soon'"],
        id="event-time-not-a-number-beside-another-event",
    ),
    # record
    pytest.param(
        lambda data: data["record"].append("plant.nope"),
        "record[8]",
        [f"unknown output port 'plant.nope' (outputs of plant: {_ports('plant', 'out')})"],
        id="record-unknown-signal",
    ),
    pytest.param(
        lambda data: data["record"].append("nobody.x"),
        "record[8]",
        [f"unknown component 'nobody' (components: {CIRCLES_COMPONENTS})"],
        id="record-unknown-component",
    ),
    pytest.param(
        lambda data: data["record"].append("plant.p_BT_B[1]"),
        "record[8]",
        ["record whole ports"],
        id="record-an-element",
    ),
    # metrics
    pytest.param(
        put("metrics", "bogus"),
        "metrics",
        [
            "expected one of none, circles, static_noise, gravity_calibration, contact_scan, "
            "release, teleecho, probe_data, clinical, got 'bogus'"
        ],
        id="metrics-unknown-set",
    ),
    pytest.param(
        put("metrics", "gravity_calibration"),
        "metrics",
        ["the gravity_calibration metrics need a component of kind 'sequencer'; there is none"],
        id="metrics-component-missing",
    ),
    pytest.param(
        put("metrics", ["circles"]),
        "metrics",
        ["expected one of none, circles", "got ['circles']"],
        id="metrics-is-a-list",
    ),
    # a given FMU
    pytest.param(
        put("components/fse103/fmu", "nope/fse103.fmu"),
        "components.fse103.fmu",
        ["no such FMU 'nope/fse103.fmu'"],
        id="fmu-does-not-exist",
    ),
    # the rest of the file
    pytest.param(
        drop("name"),
        "name",
        ["missing"],
        id="name-missing",
    ),
    pytest.param(
        put("components", {}),
        "components",
        ["expected at least one component"],
        id="no-components",
    ),
    pytest.param(
        put("description", 5),
        "description",
        ["expected a string, got 5"],
        id="description-not-a-string",
    ),
]


@pytest.mark.parametrize(("mutate", "where", "fragments"), BAD_SCENARIOS)
def test_bad_scenario_exits_2_with_one_line_naming_file_and_yaml_path(
    tmp_path, capsys, mutate, where, fragments
):
    data = circles()
    mutate(data)
    path = write_scenario(tmp_path, data)
    out_dir = tmp_path / "out"
    before = files_under(tmp_path)

    status, out, err = run_cli([str(path), "--engine", "inprocess", "--out", str(out_dir)], capsys)

    assert_one_line_rejection(status, out, err, f"{path}: {where}: ")
    for fragment in fragments:
        assert fragment in err, err
    assert not out_dir.exists()
    assert files_under(tmp_path) == before  # no runs/, no staging directory, no summary.json
    # the library raises the same one line as a ConfigError
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    assert f"hoh-cosim: {info.value}\n" == err


@pytest.mark.parametrize("position", [0, 3, 8, 19])
def test_out_of_range_element_names_the_connection_and_the_element(tmp_path, capsys, position):
    # the example, with the bad connection at different places in the list
    data = circles()
    del data["connections"][8]  # ft150.wrench_S -> estimator.wrench_S, replaced below
    data["connections"].insert(
        position, {"from": "ft150.wrench_S[6]", "to": "estimator.wrench_S[7]"}
    )
    (tmp_path / "scenarios").mkdir()
    write_scenario(tmp_path / "scenarios", data, "x.yaml")

    status, out, err = run_cli(
        ["scenarios/x.yaml", "--engine", "inprocess", "--out", "out"], capsys
    )

    assert_one_line_rejection(
        status,
        out,
        err,
        f"scenarios/x.yaml: connections[{position}].to: unknown port 'estimator.wrench_S[7]'",
    )
    assert "(wrench_S has elements 1 to 6)" in err
    assert not (tmp_path / "out").exists()


def test_invalid_yaml_names_line_and_column(tmp_path, capsys):
    path = tmp_path / "broken.yaml"
    path.write_text("name: broken\nduration_s: 30: 5\ncomponents: {}\n", encoding="utf-8")
    out_dir = tmp_path / "out"

    status, out, err = run_cli([str(path), "--engine", "inprocess", "--out", str(out_dir)], capsys)

    assert_one_line_rejection(status, out, err, f"{path}: line 2, column 15: not valid YAML: ")
    assert "mapping values are not allowed here" in err
    assert not out_dir.exists()


def test_invalid_yaml_in_a_flow_mapping_names_line_and_column(tmp_path, capsys):
    text = CIRCLES.read_text(encoding="utf-8").replace("  ft150: {}\n", "  ft150: {every: 2\n", 1)
    path = tmp_path / "broken.yaml"
    path.write_text(text, encoding="utf-8")

    status, out, err = run_cli([str(path), "--engine", "inprocess", "--out", "x"], capsys)

    assert_one_line_rejection(status, out, err, f"{path}: line ")
    assert ", column " in err
    assert "not valid YAML: " in err


def test_scenario_that_is_not_a_mapping(tmp_path, capsys):
    path = tmp_path / "list.yaml"
    path.write_text("- circles\n", encoding="utf-8")
    status, out, err = run_cli([str(path), "--engine", "inprocess"], capsys)
    assert_one_line_rejection(status, out, err, f"{path}: expected a mapping, got ['circles']")


def test_missing_scenario_file(tmp_path, capsys):
    path = tmp_path / "nope.yaml"
    status, out, err = run_cli([str(path), "--engine", "inprocess", "--out", "out"], capsys)
    assert_one_line_rejection(status, out, err)
    assert err == f"hoh-cosim: {path}: no such file\n"
    assert list(tmp_path.iterdir()) == []


# --- extends ---------------------------------------------------------------------------------


def derived(base: str, **changes: Any) -> dict[str, Any]:
    return {"extends": base, "name": "derived", **changes}


def test_extends_a_missing_base(tmp_path, capsys):
    path = write_scenario(tmp_path, derived("missing.yaml"), "derived.yaml")
    out_dir = tmp_path / "out"
    status, out, err = run_cli([str(path), "--engine", "inprocess", "--out", str(out_dir)], capsys)
    assert_one_line_rejection(
        status, out, err, f"{path}: extends: no such scenario 'missing.yaml' (looked for "
    )
    assert not out_dir.exists()


def test_extends_cycle(tmp_path, capsys):
    a = write_scenario(tmp_path, {**circles(), "extends": "b.yaml"}, "a.yaml")
    b = write_scenario(tmp_path, {**circles(), "extends": "a.yaml"}, "b.yaml")
    out_dir = tmp_path / "out"
    status, out, err = run_cli([str(a), "--engine", "inprocess", "--out", str(out_dir)], capsys)
    assert_one_line_rejection(status, out, err)
    assert err.startswith((f"hoh-cosim: {a}: extends: ", f"hoh-cosim: {b}: extends: ")), err
    assert "(a cycle)" in err
    assert not out_dir.exists()


def test_extends_itself(tmp_path, capsys):
    a = write_scenario(tmp_path, {**circles(), "extends": "a.yaml"}, "a.yaml")
    status, out, err = run_cli([str(a), "--engine", "inprocess", "--out", "x"], capsys)
    assert_one_line_rejection(status, out, err, f"{a}: extends: 'a.yaml' extends this file again")


def test_extends_reports_a_mistake_in_the_base_against_the_base(tmp_path, capsys):
    base_data = circles()
    base_data["components"]["controller"]["every"] = 0
    base = write_scenario(tmp_path, base_data, "base.yaml")
    path = write_scenario(tmp_path, derived("base.yaml"), "derived.yaml")
    status, out, err = run_cli([str(path), "--engine", "inprocess", "--out", "x"], capsys)
    assert_one_line_rejection(status, out, err, f"{base}: components.controller.every: ")


def test_extends_reports_a_mistake_in_the_change_against_the_derived_file(tmp_path, capsys):
    write_scenario(tmp_path, circles(), "base.yaml")
    change = {"components": {"estimator": {"params": {"nope": 1.0}}}}
    path = write_scenario(tmp_path, derived("base.yaml", **change), "derived.yaml")
    status, out, err = run_cli([str(path), "--engine", "inprocess", "--out", "x"], capsys)
    assert_one_line_rejection(status, out, err, f"{path}: components.estimator.params.nope: ")


# --- command-line options --------------------------------------------------------------------


def _cli_on_circles(tmp_path, capsys, *options: str) -> tuple[int, str, str, Path]:
    out_dir = tmp_path / "out"
    # a short duration, so a check that wrongly lets the run start still ends quickly
    argv = [str(CIRCLES), "--engine", "inprocess", "--quiet", "--out", str(out_dir), *options]
    if "--duration" not in options:
        argv += ["--duration", "0.05"]
    status, out, err = run_cli(argv, capsys)
    return status, out, err, out_dir


@pytest.mark.parametrize(
    ("options", "message"),
    [
        pytest.param(
            ["--set", "nobody.x=1"],
            f"--set nobody.x: unknown component 'nobody' (components: {CIRCLES_COMPONENTS})",
            id="set-unknown-component",
        ),
        pytest.param(
            ["--set", "controller.contact_compensation"],
            "--set controller.contact_compensation: expected component.parameter=value",
            id="set-without-equals",
        ),
        pytest.param(
            ["--set", "controller=1"],
            "--set controller=1: expected component.parameter=value",
            id="set-without-parameter",
        ),
        pytest.param(
            ["--set", "controller.translation.slope=abc"],
            "--set controller.translation.slope: expected a list of 3 numbers, got 'abc'",
            id="set-wrong-type",
        ),
        pytest.param(
            ["--set", "controller.contact_compensation=1"],
            "--set controller.contact_compensation: expected true or false, got 1",
            id="set-boolean-given-a-number",
        ),
        pytest.param(
            ["--set", "controller.nope=1"],
            f"--set controller.nope: unknown parameter of ControllerParams "
            f"(one of: {_fields(ControllerParams)})",
            id="set-unknown-parameter",
        ),
        pytest.param(
            ["--duration", "-1"],
            f"{CIRCLES}: --duration: expected a number > 0, got -1.0",
            id="negative-duration",
        ),
        pytest.param(
            ["--duration", "0"],
            f"{CIRCLES}: --duration: expected a number > 0, got 0.0",
            id="zero-duration",
        ),
        pytest.param(
            ["--duration", "nan"],
            f"{CIRCLES}: --duration: expected a number, got nan",
            id="nan-duration",
        ),
        pytest.param(
            ["--seed", "-3"],
            "--seed: expected an integer >= 0, got -3",
            id="negative-seed",
        ),
        pytest.param(
            ["--set", "operator.task=square"],
            "--set operator.task: expected one of off, hold, circle",
            id="set-string-parameter-out-of-its-choices",
        ),
        pytest.param(
            ["--set", "controller.translation.law=[1,"],
            "--set controller.translation.law: ",
            id="set-value-not-valid-yaml",
        ),
        pytest.param(
            ["--duration", "0.0004"],
            f"{CIRCLES}: --duration: ",
            id="duration-shorter-than-one-tick",
        ),
    ],
)
def test_bad_option_exits_2_with_one_line(tmp_path, capsys, options, message):
    before = files_under(tmp_path)
    status, out, err, out_dir = _cli_on_circles(tmp_path, capsys, *options)
    assert_one_line_rejection(status, out, err, message)
    assert not out_dir.exists()
    assert files_under(tmp_path) == before


@pytest.mark.parametrize(
    ("options", "fragments"),
    [
        pytest.param(
            ["--engine", "bogus"], ["--engine", "invalid choice: 'bogus'"], id="engine-bogus"
        ),
        pytest.param(
            ["--duration", "abc"], ["--duration", "invalid float value: 'abc'"], id="duration-abc"
        ),
        pytest.param(["--seed", "1.5"], ["--seed", "invalid int value: '1.5'"], id="seed-1.5"),
        pytest.param(["--bogus"], ["unrecognized arguments: --bogus"], id="unknown-option"),
    ],
)
def test_usage_error_exits_2_with_one_line(tmp_path, capsys, options, fragments):
    status, out, err, out_dir = _cli_on_circles(tmp_path, capsys, *options)
    assert_one_line_rejection(status, out, err)
    for fragment in fragments:
        assert fragment in err, err
    assert not out_dir.exists()
    assert list(tmp_path.iterdir()) == []


def test_usage_error_is_returned_not_raised(capsys):
    status = main([str(CIRCLES), "--engine", "bogus"])
    assert status == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_out_refuses_a_non_empty_directory_without_summary(tmp_path, capsys):
    out_dir = tmp_path / "mine"
    out_dir.mkdir()
    (out_dir / "notes.txt").write_text("my notes\n", encoding="utf-8")
    (out_dir / "data").mkdir()
    (out_dir / "data" / "a.csv").write_text("1,2\n", encoding="utf-8")
    before = {p: (p.stat().st_mtime_ns, p.is_file() and p.read_bytes()) for p in out_dir.rglob("*")}
    siblings = files_under(tmp_path)

    status, out, err, _ = _cli_on_circles(tmp_path, capsys, "--out", str(out_dir))

    assert_one_line_rejection(status, out, err, f"--out {out_dir}: exists, is not empty ")
    assert "summary.json" in err
    after = {p: (p.stat().st_mtime_ns, p.is_file() and p.read_bytes()) for p in out_dir.rglob("*")}
    assert after == before
    assert files_under(tmp_path) == siblings  # no staging directory beside it either


def test_out_refuses_an_existing_file(tmp_path, capsys):
    target = tmp_path / "results"
    target.write_text("not a directory\n", encoding="utf-8")
    status, out, err, _ = _cli_on_circles(tmp_path, capsys, "--out", str(target))
    assert_one_line_rejection(status, out, err, f"--out {target}: exists and is not a directory")
    assert target.read_text(encoding="utf-8") == "not a directory\n"


def test_load_scenario_rejects_a_negative_seed_override():
    with pytest.raises(ConfigError, match="seed"):
        load_scenario(CIRCLES, seed=-3)


def test_scenario_shorter_than_one_tick_is_rejected_when_loaded(tmp_path):
    data = circles()
    data["dt_s"] = 100.0
    path = write_scenario(tmp_path, data)
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    assert str(info.value).startswith((f"{path}: dt_s: ", f"{path}: duration_s: "))


# --- positive controls: the fixtures are known-good ------------------------------------------


@pytest.mark.parametrize("name", ["circles", "contact_scan", "gravity_calibration"])
def test_real_scenarios_load(name):
    scenario = load_scenario(SCENARIOS / f"{name}.yaml")
    assert scenario.name == name


def test_unmodified_circles_loads_and_set_override_is_reflected():
    plain = load_scenario(CIRCLES)
    assert plain.components["controller"].params.contact_compensation is True

    changed = load_scenario(CIRCLES, ["controller.contact_compensation=false"])
    assert changed.components["controller"].params.contact_compensation is False
    # nothing else moved
    moved = [
        a.name
        for a, b in zip(
            leaves(plain.components["controller"].params),
            leaves(changed.components["controller"].params),
            strict=True,
        )
        if a != b
    ]
    assert moved == ["contact_compensation"]
    assert changed.connections == plain.connections


def test_circles_round_trips_through_the_fixture_writer(tmp_path):
    # what every bad scenario above starts from loads as the original does
    path = write_scenario(tmp_path, circles())
    copy = load_scenario(path)
    original = load_scenario(CIRCLES)
    assert copy.connections == original.connections
    assert copy.record == original.record
    assert list(copy.components) == list(original.components)
