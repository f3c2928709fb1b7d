"""A rig's configuration file (hoh_cosim.hardware.config.load_config): defaults, every key, and the
one-line errors `FILE: YAML.PATH: problem` for what is wrong, plus the `--set` overrides.

Every file is written to tmp_path; the expected values are spelled out here, not taken from the
module under test.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.control.controller import ControllerParams
from hoh_cosim.control.estimator import EstimatorParams
from hoh_cosim.errors import ConfigError
from hoh_cosim.hardware.config import load_config
from hoh_cosim.params import leaves

# the keys the module's docstring documents
TOP_KEYS = (
    "robot",
    "ft150",
    "probe",
    "calibration",
    "preset",
    "rebias",
    "estimator",
    "controller",
    "log_dir",
    "stale_stop_s",
)
ROBOT_KEYS = (
    "host",
    "frequency_hz",
    "watchdog_hz",
    "acceleration",
    "sensor_rotvec_T",
    "realtime_priority",
)
MINIMAL = "robot:\n  host: 192.168.1.10\nprobe: null\n"
WITH_PROBE = "robot:\n  host: 192.168.1.10\nprobe:\n  device: /dev/ttyACM0\n"


def values_of(params: object) -> dict[str, object]:
    """A parameter tree's scalars by name (its dataclasses hold arrays: `==` would not do)."""
    return {leaf.name: leaf.value for leaf in leaves(params)}


def write(directory: Path, text: str, name: str = "rig.yaml") -> Path:
    path = directory / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def rejection(path: Path, overrides: tuple[str, ...] = ()) -> str:
    """The message of the ConfigError that loading `path` must raise: a single line."""
    with pytest.raises(ConfigError) as info:
        load_config(path, overrides)
    message = str(info.value)
    assert "\n" not in message, message
    return message


def listed_keys(message: str, prefix: str) -> set[str]:
    """The keys an 'unknown key (expected one of: ...)' message lists after `prefix`."""
    match = re.fullmatch(re.escape(prefix) + r"unknown key \(expected one of: (.*)\)", message)
    assert match is not None, message
    return set(match[1].split(", "))


# --- defaults -----------------------------------------------------------------------------------


def test_a_minimal_config_loads_with_the_documented_defaults(tmp_path):
    path = write(tmp_path, "robot:\n  host: 192.168.1.10\nprobe:\n  device: /dev/ttyACM0\n")
    config = load_config(path)

    assert config.path == path
    assert config.robot.host == "192.168.1.10"
    assert config.robot.frequency_hz == -1.0
    assert config.robot.watchdog_hz == 20.0
    assert config.robot.acceleration == 1.0
    assert config.robot.realtime_priority is None
    # R_TS: a rotation of pi about x
    np.testing.assert_allclose(config.robot.R_TS, np.diag([1.0, -1.0, -1.0]), atol=1e-12)

    assert config.ft150.host == "192.168.1.10"  # the robot's by default
    assert config.ft150.port == 63351
    assert config.ft150.zero_on_start is False

    assert config.probe is not None
    assert config.probe.device == "/dev/ttyACM0"
    assert (config.probe.framing, config.probe.byte_order) == ("auto", "auto")
    assert config.probe.baudrate == 115200

    assert config.calibration is None
    assert config.log_dir == tmp_path / "sessions"
    rebias = config.rebias
    assert (rebias.samples, rebias.max_speed_m_s, rebias.tolerance_N) == (500, 0.002, 2.0)
    assert (rebias.tolerance_Nm, rebias.timeout_s) == (0.2, 15.0)
    assert config.stale_stop_s == 0.25

    # with a probe sensor, the blocks' defaults unchanged
    assert values_of(config.estimator) == values_of(EstimatorParams())
    assert values_of(config.controller) == values_of(ControllerParams())
    assert config.estimator.use_probe is True
    assert config.controller.use_probe is True


def test_the_ft150_host_defaults_to_the_robots_but_may_differ(tmp_path):
    same = load_config(write(tmp_path, "robot: {host: 10.0.0.2}\nprobe: null\n", "a.yaml"))
    other = load_config(
        write(tmp_path, "robot: {host: 10.0.0.2}\nft150: {host: 10.0.0.3}\nprobe: null\n", "b.yaml")
    )
    assert same.ft150.host == "10.0.0.2"
    assert other.ft150.host == "10.0.0.3"
    assert other.robot.host == "10.0.0.2"


def test_probe_null_turns_the_probe_off_in_the_estimator_and_the_controller(tmp_path):
    config = load_config(write(tmp_path, MINIMAL))
    assert config.probe is None
    assert config.estimator.use_probe is False
    assert config.controller.use_probe is False
    # nothing else changes
    assert values_of(config.estimator) == {
        **values_of(EstimatorParams()),
        "use_probe": False,
    }
    assert values_of(config.controller) == {
        **values_of(ControllerParams()),
        "use_probe": False,
    }


def test_probe_null_wins_over_use_probe_in_the_blocks_sections(tmp_path):
    text = MINIMAL + "estimator: {use_probe: true}\ncontroller: {use_probe: true}\n"
    config = load_config(write(tmp_path, text))
    assert config.estimator.use_probe is False
    assert config.controller.use_probe is False


@pytest.mark.parametrize(
    "text",
    [
        pytest.param("robot: {host: h}\n", id="no-probe-section"),
        pytest.param("robot: {host: h}\nprobe: {}\n", id="empty-probe-section"),
        pytest.param("robot: {host: h}\nprobe: {framing: seed18}\n", id="probe-without-device"),
    ],
)
def test_the_probe_is_required_unless_it_is_null(tmp_path, text):
    path = write(tmp_path, text)
    assert rejection(path) == (
        f"{path}: probe.device: missing (or write `probe: null` for no probe sensor)"
    )


def test_calibration_and_log_dir_are_paths_from_the_config_files_directory(tmp_path, monkeypatch):
    rig = tmp_path / "rig"
    text = MINIMAL + "calibration: cal/calibration.json\nlog_dir: logs/today\n"
    write(rig, text)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)

    absolute = load_config(rig / "rig.yaml")
    assert absolute.calibration == rig / "cal" / "calibration.json"
    assert absolute.log_dir == rig / "logs" / "today"

    # a config named relative to the working directory: the paths still lead next to it
    relative = load_config(Path("..") / "rig" / "rig.yaml")
    assert relative.calibration is not None
    assert relative.calibration.resolve() == (rig / "cal" / "calibration.json").resolve()
    assert relative.log_dir.resolve() == (rig / "logs" / "today").resolve()


def test_absolute_calibration_and_log_dir_stay_as_written(tmp_path):
    cal, logs = tmp_path / "shared" / "calibration.json", tmp_path / "shared" / "sessions"
    config = load_config(
        write(tmp_path / "rig", MINIMAL + f"calibration: {cal}\nlog_dir: {logs}\n")
    )
    assert config.calibration == cal
    assert config.log_dir == logs


def test_an_empty_config_file_asks_for_the_robots_host(tmp_path):
    path = write(tmp_path, "")
    assert rejection(path) == f"{path}: robot.host: missing (the robot's address)"


# --- every key ----------------------------------------------------------------------------------

FULL = """\
robot:
  host: 192.168.1.10
  frequency_hz: 500
  watchdog_hz: 10
  acceleration: 0.5
  sensor_rotvec_T: [0, 0, 1.5707963267948966]
ft150:
  host: 192.168.1.11
  port: 63400
  zero_on_start: true
probe:
  device: /dev/ttyUSB3
  framing: guide20
  byte_order: big
  baudrate: 230400
calibration: calibration.json
rebias:
  samples: 250
  max_speed_m_s: 0.004
  tolerance_N: 3.5
  tolerance_Nm: 0.35
  timeout_s: 7.5
estimator:
  filter: butterworth
  tool: {mass_kg: 0.6}
  butterworth: {order: 3, cutoff_hz: 8.0}
controller:
  contact_compensation: false
  virtual_fixture: true
  translation: {slope: [0.01, 0.02, 0.03]}
  limits: {max_linear_speed: 0.05}
log_dir: /var/log/hoh
"""


def test_a_full_config_loads_every_key(tmp_path):
    config = load_config(write(tmp_path, FULL))

    robot = config.robot
    assert (robot.host, robot.frequency_hz, robot.watchdog_hz, robot.acceleration) == (
        "192.168.1.10",
        500.0,
        10.0,
        0.5,
    )
    # a quarter turn about z
    np.testing.assert_allclose(
        robot.R_TS, [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], atol=1e-12
    )
    assert (config.ft150.host, config.ft150.port, config.ft150.zero_on_start) == (
        "192.168.1.11",
        63400,
        True,
    )
    assert config.probe is not None
    assert (config.probe.device, config.probe.framing, config.probe.byte_order) == (
        "/dev/ttyUSB3",
        "guide20",
        "big",
    )
    assert config.probe.baudrate == 230400
    assert config.calibration == tmp_path / "calibration.json"
    rebias = config.rebias
    assert (rebias.samples, rebias.max_speed_m_s, rebias.tolerance_N) == (250, 0.004, 3.5)
    assert (rebias.tolerance_Nm, rebias.timeout_s) == (0.35, 7.5)
    assert config.log_dir == Path("/var/log/hoh")

    estimator = config.estimator
    assert estimator.filter == "butterworth"
    assert estimator.tool.mass_kg == 0.6
    assert (estimator.butterworth.order, estimator.butterworth.cutoff_hz) == (3, 8.0)
    assert estimator.use_probe is True
    controller = config.controller
    assert controller.contact_compensation is False
    assert controller.virtual_fixture is True
    np.testing.assert_array_equal(controller.translation.slope, [0.01, 0.02, 0.03])
    assert controller.limits.max_linear_speed == 0.05
    # what the file does not set keeps its default
    assert controller.limits.max_angular_speed == ControllerParams().limits.max_angular_speed
    assert values_of(estimator.hand_force_kalman) == values_of(EstimatorParams().hand_force_kalman)


def test_robot_realtime_priority_is_read(tmp_path):
    path = write(tmp_path, "robot: {host: h, realtime_priority: 80}\nprobe: null\n")
    assert load_config(path).robot.realtime_priority == 80


def test_stale_stop_s_is_read(tmp_path):
    path = write(tmp_path, MINIMAL + "stale_stop_s: 0.5\n")
    assert load_config(path).stale_stop_s == 0.5


@pytest.mark.parametrize("frequency", [-1, 1, 125, 1000])
def test_frequency_hz_takes_minus_one_or_1_to_1000(tmp_path, frequency):
    path = write(tmp_path, f"robot: {{host: h, frequency_hz: {frequency}}}\nprobe: null\n")
    assert load_config(path).robot.frequency_hz == float(frequency)


# --- one-line errors ----------------------------------------------------------------------------

# (file text, message after "FILE: ")
BAD_CONFIGS = [
    pytest.param(
        "robot: {frequency_hz: 500}\nprobe: null\n",
        "robot.host: missing (the robot's address)",
        id="missing-robot-host",
    ),
    pytest.param("probe: null\n", "robot.host: missing (the robot's address)", id="no-robot"),
    pytest.param(
        "robot: {host: ''}\nprobe: null\n",
        "robot.host: expected a non-empty string, got ''",
        id="empty-host",
    ),
    pytest.param(
        "robot: {host: 5}\nprobe: null\n",
        "robot.host: expected a non-empty string, got 5",
        id="host-not-a-string",
    ),
    pytest.param(
        "robot: 192.168.1.10\nprobe: null\n",
        "robot: expected a mapping, got '192.168.1.10'",
        id="robot-not-a-mapping",
    ),
    pytest.param("- robot\n- probe\n", "expected a mapping, got ['robot', 'probe']", id="a-list"),
    pytest.param(
        "robot: {host: h, frequency_hz: 0}\nprobe: null\n",
        "robot.frequency_hz: expected -1 or 1 to 1000 Hz, got 0.0",
        id="frequency-zero",
    ),
    pytest.param(
        "robot: {host: h, frequency_hz: 1001}\nprobe: null\n",
        "robot.frequency_hz: expected -1 or 1 to 1000 Hz, got 1001.0",
        id="frequency-too-high",
    ),
    pytest.param(
        "robot: {host: h, frequency_hz: -2}\nprobe: null\n",
        "robot.frequency_hz: expected -1 or 1 to 1000 Hz, got -2.0",
        id="frequency-negative",
    ),
    pytest.param(
        "robot: {host: h, frequency_hz: fast}\nprobe: null\n",
        "robot.frequency_hz: expected a number, got 'fast'",
        id="frequency-not-a-number",
    ),
    pytest.param(
        "robot: {host: h, watchdog_hz: 0}\nprobe: null\n",
        "robot.watchdog_hz: expected a number > 0, got 0",
        id="watchdog-zero",
    ),
    pytest.param(
        "robot: {host: h, acceleration: -1.0}\nprobe: null\n",
        "robot.acceleration: expected a number > 0, got -1.0",
        id="acceleration-negative",
    ),
    pytest.param(
        "robot: {host: h, sensor_rotvec_T: [3.14, 0]}\nprobe: null\n",
        "robot.sensor_rotvec_T: expected a list of 3 numbers, got [3.14, 0]",
        id="rotvec-two-numbers",
    ),
    pytest.param(
        "robot: {host: h, sensor_rotvec_T: [3.14, 0, 0, 0]}\nprobe: null\n",
        "robot.sensor_rotvec_T: expected a list of 3 numbers, got [3.14, 0, 0, 0]",
        id="rotvec-four-numbers",
    ),
    pytest.param(
        "robot: {host: h, sensor_rotvec_T: 3.14}\nprobe: null\n",
        "robot.sensor_rotvec_T: expected a list of 3 numbers, got 3.14",
        id="rotvec-a-number",
    ),
    pytest.param(
        "robot: {host: h, sensor_rotvec_T: [0, 0, x]}\nprobe: null\n",
        "robot.sensor_rotvec_T[3]: expected a number, got 'x'",
        id="rotvec-element-not-a-number",
    ),
    pytest.param(
        "robot: {host: h}\nft150: {port: 0}\nprobe: null\n",
        "ft150.port: expected an integer >= 1, got 0",
        id="port-zero",
    ),
    pytest.param(
        "robot: {host: h}\nft150: {port: 65536}\nprobe: null\n",
        "ft150.port: expected an integer <= 65535, got 65536",
        id="port-too-high",
    ),
    pytest.param(
        "robot: {host: h}\nft150: {port: '63351'}\nprobe: null\n",
        "ft150.port: expected an integer >= 1, got '63351'",
        id="port-a-string",
    ),
    pytest.param(
        "robot: {host: h}\nft150: {zero_on_start: maybe}\nprobe: null\n",
        "ft150.zero_on_start: expected true or false, got 'maybe'",
        id="zero-on-start-not-a-boolean",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: {device: /dev/ttyACM0, framing: seed20}\n",
        "probe.framing: expected one of auto, seed18, guide20, got 'seed20'",
        id="bad-framing",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: {device: /dev/ttyACM0, byte_order: middle}\n",
        "probe.byte_order: expected one of auto, little, big, got 'middle'",
        id="bad-byte-order",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: {device: /dev/ttyACM0, baudrate: 0}\n",
        "probe.baudrate: expected an integer >= 1, got 0",
        id="baudrate-zero",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: null\nrebias: {samples: 0}\n",
        "rebias.samples: expected an integer >= 1, got 0",
        id="rebias-samples-zero",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: null\nrebias: {tolerance_N: -2}\n",
        "rebias.tolerance_N: expected a number > 0, got -2",
        id="rebias-tolerance-negative",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: null\ncalibration: 5\n",
        "calibration: expected a non-empty string, got 5",
        id="calibration-not-a-path",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: null\nlog_dir: ''\n",
        "log_dir: expected a non-empty string, got ''",
        id="empty-log-dir",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: null\nestimator: {filter: median}\n",
        "estimator.filter: expected one of kalman, steady_kalman, lead_lowpass, butterworth, "
        "one_euro, none, "
        "got 'median'",
        id="estimator-value-rejected",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: null\ncontroller: {limits: {max_linear_speed: -0.1}}\n",
        "controller.limits.max_linear_speed: must be > 0.0, got -0.1",
        id="negative-speed-limit",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: null\ncontroller: {contact_compensation: 1}\n",
        "controller.contact_compensation: expected true or false, got 1",
        id="controller-boolean-as-number",
    ),
    pytest.param(
        "robot: {host: h}\nprobe: null\nestimator: 5\n",
        "estimator: expected a mapping of parameters, got 5",
        id="estimator-not-a-mapping",
    ),
]


@pytest.mark.parametrize(("text", "problem"), BAD_CONFIGS)
def test_a_bad_value_is_one_line_naming_file_path_expected_and_got(tmp_path, text, problem):
    path = write(tmp_path, text)
    assert rejection(path) == f"{path}: {problem}"


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        (1, "expected an integer >= 2, got 1"),
        (99, "expected an integer <= 98, got 99"),
        ("high", "expected an integer >= 2, got 'high'"),
    ],
)
def test_realtime_priority_out_of_range(tmp_path, value, problem):
    path = write(tmp_path, f"robot: {{host: h, realtime_priority: {value}}}\nprobe: null\n")
    assert rejection(path) == f"{path}: robot.realtime_priority: {problem}"


def test_an_unknown_top_level_key_lists_the_known_ones(tmp_path):
    path = write(tmp_path, MINIMAL + "robots: {host: h}\n")
    assert listed_keys(rejection(path), f"{path}: robots: ") == set(TOP_KEYS)


def test_an_unknown_key_in_robot_lists_the_known_ones(tmp_path):
    path = write(tmp_path, "robot: {host: h, hostname: x}\nprobe: null\n")
    keys = listed_keys(rejection(path), f"{path}: robot.hostname: ")
    assert keys == set(ROBOT_KEYS)


@pytest.mark.parametrize(
    ("section", "key", "known"),
    [
        ("ft150", "adress", {"host", "port", "zero_on_start"}),
        ("probe", "baud", {"sensor", "device", "framing", "byte_order", "baudrate"}),
        (
            "rebias",
            "tolerance",
            {"samples", "max_speed_m_s", "tolerance_N", "tolerance_Nm", "timeout_s"},
        ),
    ],
)
def test_an_unknown_key_in_a_section_lists_the_known_ones(tmp_path, section, key, known):
    extra = {"probe": "device: /dev/ttyACM0, "}.get(section, "")
    text = f"robot: {{host: h}}\n{section}: {{{extra}{key}: 1}}\n"
    if section != "probe":
        text += "probe: null\n"
    path = write(tmp_path, text)
    assert listed_keys(rejection(path), f"{path}: {section}.{key}: ") == known


def test_an_unknown_estimator_parameter_is_named_by_its_path(tmp_path):
    path = write(tmp_path, MINIMAL + "estimator: {filtre: kalman}\n")
    message = rejection(path)
    fields = ", ".join(f.name for f in dataclasses.fields(EstimatorParams))
    assert message == (
        f"{path}: estimator.filtre: unknown parameter of EstimatorParams (one of: {fields})"
    )


def test_an_unknown_nested_controller_parameter_is_named_by_its_path(tmp_path):
    path = write(tmp_path, MINIMAL + "controller: {limits: {max_speed: 0.1}}\n")
    message = rejection(path)
    assert message.startswith(
        f"{path}: controller.limits.max_speed: unknown parameter of LimitParams (one of: "
    )
    assert "max_linear_speed" in message


def test_invalid_yaml_names_the_line_and_column(tmp_path):
    path = write(tmp_path, "robot:\n  host: h\n\tprobe: null\n")
    message = rejection(path)
    assert message.startswith(f"{path}: line 3, column 1: not valid YAML: "), message
    assert message.endswith("that cannot start any token"), message


def test_unclosed_yaml_is_one_line(tmp_path):
    path = write(tmp_path, "robot: {host: h\n")
    message = rejection(path)
    assert re.fullmatch(
        re.escape(f"{path}: line ") + r"\d+, column \d+: not valid YAML: .+", message
    )


def test_a_missing_file(tmp_path):
    path = tmp_path / "nowhere.yaml"
    assert rejection(path) == f"{path}: no such file"


def test_a_file_that_is_not_text(tmp_path):
    path = tmp_path / "rig.yaml"
    path.write_bytes(b"robot: {host: \xff\xfe}\n")
    assert rejection(path).startswith(f"{path}: cannot read: ")


# --- --set overrides ----------------------------------------------------------------------------


def test_overrides_set_controller_and_estimator_parameters(tmp_path):
    path = write(tmp_path, MINIMAL + "controller: {limits: {max_linear_speed: 0.05}}\n")
    config = load_config(
        path,
        [
            "controller.contact_compensation=false",
            "estimator.filter=one_euro",
            "controller.translation.slope[2]=0.02",
        ],
    )
    assert config.controller.contact_compensation is False
    assert config.estimator.filter == "one_euro"
    np.testing.assert_array_equal(config.controller.translation.slope, [0.0125, 0.02, 0.0125])
    # the file's own settings and the rest stay
    assert config.controller.limits.max_linear_speed == 0.05
    assert config.controller.virtual_fixture is False
    assert values_of(config.controller) == {
        **values_of(ControllerParams()),
        "use_probe": False,
        "contact_compensation": False,
        "translation.slope[2]": 0.02,
        "limits.max_linear_speed": 0.05,
    }
    assert values_of(config.estimator) == {
        **values_of(EstimatorParams()),
        "use_probe": False,
        "filter": "one_euro",
    }


def test_without_overrides_contact_compensation_stays_on(tmp_path):
    assert load_config(write(tmp_path, MINIMAL)).controller.contact_compensation is True


def test_a_later_override_wins(tmp_path):
    config = load_config(
        write(tmp_path, MINIMAL),
        ["controller.limits.max_linear_speed=0.05", "controller.limits.max_linear_speed=0.07"],
    )
    assert config.controller.limits.max_linear_speed == 0.07


BAD_OVERRIDES = [
    pytest.param(
        "nope.x=1",
        "--set nope.x=1: expected estimator.parameter=value or controller.parameter=value",
        id="unknown-block",
    ),
    pytest.param(
        "controller.contact_compensation",
        "--set controller.contact_compensation: expected estimator.parameter=value or "
        "controller.parameter=value",
        id="no-value",
    ),
    pytest.param(
        "controller=1",
        "--set controller=1: expected estimator.parameter=value or controller.parameter=value",
        id="no-parameter",
    ),
    pytest.param(
        "controller.nope=1",
        "--set controller.nope: unknown parameter of ControllerParams (one of: "
        + ", ".join(f.name for f in dataclasses.fields(ControllerParams))
        + ")",
        id="unknown-parameter",
    ),
    pytest.param(
        "controller.contact_compensation=maybe",
        "--set controller.contact_compensation: expected true or false, got 'maybe'",
        id="not-a-boolean",
    ),
    pytest.param(
        "controller.limits.max_linear_speed=-1",
        "--set controller.limits.max_linear_speed: must be > 0.0, got -1.0",
        id="negative-speed-limit",
    ),
    pytest.param(
        "controller.translation.slope[4]=1",
        "--set controller.translation.slope[4]: unknown parameter of ControllerParams "
        "(translation.slope has elements 1 to 3)",
        id="element-out-of-range",
    ),
    pytest.param(
        "estimator.filter=median",
        "--set estimator.filter: expected one of kalman, steady_kalman, lead_lowpass, butterworth, "
        "one_euro, "
        "none, got 'median'",
        id="estimator-value-rejected",
    ),
]


@pytest.mark.parametrize(("override", "message"), BAD_OVERRIDES)
def test_a_bad_override_is_one_line(tmp_path, override, message):
    path = write(tmp_path, MINIMAL)
    assert rejection(path, (override,)) == message


def test_an_override_value_that_is_not_yaml_is_one_line(tmp_path):
    path = write(tmp_path, MINIMAL)
    message = rejection(path, ("estimator.filter=[",))
    assert message.startswith("--set estimator.filter: cannot read the value '[': ")


def test_the_new_laws_reach_the_runner_from_the_rig_file(tmp_path):
    """The filter without a peak, the variable law, release braking and the passivity controller
    are ordinary estimator and controller parameters of the rig file."""
    path = write(
        tmp_path,
        MINIMAL
        + "estimator: {filter: lead_lowpass, lead_lowpass: {cutoff_hz: 4.0}}\n"
        + "controller: {translation: {law: variable}, release: {enabled: true, hold_s: 0.2},"
        + " passivity: {enabled: true}, limits: {max_brake_accel: 8.0}}\n",
    )
    config = load_config(path)
    assert config.estimator.filter == "lead_lowpass"
    assert config.estimator.lead_lowpass.cutoff_hz == 4.0
    assert config.controller.translation.law == "variable"
    assert config.controller.release.enabled
    assert config.controller.release.hold_s == 0.2
    assert config.controller.passivity.enabled
    assert config.controller.limits.max_brake_accel == 8.0


def test_speedl_takes_the_braking_a_only_for_a_command_to_rest():
    from hoh_cosim.hardware.runner import speedl_acceleration

    rest = np.zeros(6)
    moving = np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert speedl_acceleration(rest, 1.0, 10.0) == 10.0
    assert speedl_acceleration(moving, 1.0, 10.0) == 1.0  # never faster away from rest
    assert speedl_acceleration(rest, 1.0, 0.0) == 1.0  # not braking: the rig's own
    assert speedl_acceleration(rest, 12.0, 10.0) == 12.0


# --- the probe sensor: the FSE103, the load cell or none -----------------------------------------


def test_a_load_cell_brings_its_mounting_its_rate_and_the_wrists_part_across_the_axis(tmp_path):
    from hoh_cosim.control.loadcell import LINE_RATE_HZ, R_SL_SEED

    path = write(tmp_path, "robot: {host: h}\nprobe: {sensor: loadcell, device: /dev/ttyACM0}\n")
    config = load_config(path)
    assert config.probe is not None
    assert config.probe.sensor == "loadcell"
    np.testing.assert_array_equal(config.estimator.R_SP, R_SL_SEED)
    assert config.estimator.probe_packet_period_s == pytest.approx(1.0 / LINE_RATE_HZ)
    assert config.controller.probe_period_s == pytest.approx(1.0 / LINE_RATE_HZ)
    assert config.estimator.probe_correction.across_from_wrist_s > 0.0
    # the rig's own value stands
    path = write(
        tmp_path,
        "robot: {host: h}\nprobe: {sensor: loadcell, device: /dev/ttyACM0}\n"
        "estimator: {probe_correction: {across_from_wrist_s: 1.5}}\n",
    )
    assert load_config(path).estimator.probe_correction.across_from_wrist_s == 1.5


def test_probe_sensor_on_the_command_line_replaces_the_files(tmp_path):
    path = write(tmp_path, "robot: {host: h}\nprobe: {device: /dev/ttyACM0}\n")
    assert load_config(path).probe.sensor == "fse103"
    assert load_config(path, probe_sensor="loadcell").probe.sensor == "loadcell"
    config = load_config(path, probe_sensor="none")
    assert config.probe is None
    assert config.estimator.use_probe is False
    with pytest.raises(
        ConfigError, match=r"--probe-sensor: expected one of fse103, loadcell, none"
    ):
        load_config(path, probe_sensor="honeywell")


def test_the_fse103s_framing_on_a_load_cell_is_refused(tmp_path):
    path = write(
        tmp_path, "robot: {host: h}\nprobe: {sensor: loadcell, device: /dev/x, framing: seed18}\n"
    )
    assert rejection(path) == f"{path}: probe.framing: is the FSE103's; the load cell has none"
