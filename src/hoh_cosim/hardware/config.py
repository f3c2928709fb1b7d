"""A rig's configuration: one YAML file, checked like a scenario (same one-line errors).

    robot:
      host: 192.168.1.10
      frequency_hz: -1            # the controller's own rate: 125 Hz on a CB3, 500 Hz on an e-series
      watchdog_hz: 20             # ur-rtde's watchdog: the robot stops if we fall silent for 50 ms
      acceleration: 1.0           # speedL's a [m/s²], above the controller's own 1 m/s² clamp
      sensor_rotvec_T: [3.141592653589793, 0, 0]   # the wrist sensor S in the TCP frame (R_TS)
      realtime_priority: 80       # optional: SCHED_FIFO for the loop (Linux, needs the right)
    ft150:
      host: 192.168.1.10          # default: the robot's
      port: 63351
      zero_on_start: false        # also send SET ZRO to port 63350 before the rebias
    probe:                        # or `probe: null` without a probe sensor
      sensor: fse103              # or loadcell (the Honeywell Model 31 behind its Arduino)
      device: /dev/ttyACM0
      framing: auto               # FSE103: seed18, guide20 or auto
      byte_order: auto            # FSE103: little, big or auto
      baudrate: 115200
    calibration: calibration.json # from `hoh-cosim hw calibrate` (path from this file)
    rebias:
      samples: 500                # averaged while the robot holds still (seed 3.B.1)
      max_speed_m_s: 0.002
      tolerance_N: 2.0            # mean minus (weight + calibrated offset) must stay within these
      tolerance_Nm: 0.2
      timeout_s: 15.0
    preset: clinical              # the estimator's and the controller's parameters before the
                                  # sections below (hoh_cosim.presets; default: DEFAULT_PRESET)
    estimator: {...}              # EstimatorParams overrides (the tool comes from the calibration);
                                  # its packet periods and use_probe are the rig's, for both blocks
    controller: {...}             # ControllerParams overrides (gains, limits, fixture, ...), e.g.
                                  # {translation: {law: variable}, release: {enabled: true},
                                  #  passivity: {enabled: true}}; estimator: {filter: lead_lowpass}
    log_dir: sessions             # session logs (MCAP), path from this file
    stale_stop_s: 0.25            # a stream silent this long ends the session; a shorter gap
                                  # (over 3 packet periods) only makes the command zero

Only `robot.host` is required.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.control.controller import ControllerParams
from hoh_cosim.control.cycle import PROBE_SENSORS, SensorSetup
from hoh_cosim.control.estimator import EstimatorParams
from hoh_cosim.control.frames import rotvec_to_matrix
from hoh_cosim.control.loadcell import estimator_defaults
from hoh_cosim.control.vectors import Rot3
from hoh_cosim.errors import ConfigError
from hoh_cosim.params import from_mapping, override
from hoh_cosim.presets import DEFAULT_PRESET, Preset, changed_from, load_preset
from hoh_cosim.yamlfile import Where, parse_value, read_yaml

__all__ = [
    "FT150Config",
    "HardwareConfig",
    "ProbeConfig",
    "RebiasConfig",
    "RobotConfig",
    "load_config",
    "with_overrides",
]

_R_TS_DEFAULT = (np.pi, 0.0, 0.0)


@dataclass(frozen=True)
class RobotConfig:
    host: str
    frequency_hz: float = -1.0
    watchdog_hz: float = 20.0
    acceleration: float = 1.0
    R_TS: Rot3 = dataclasses.field(default_factory=lambda: rotvec_to_matrix(_R_TS_DEFAULT))
    realtime_priority: int | None = None  # SCHED_FIFO for the loop (Linux; needs the right)


@dataclass(frozen=True)
class FT150Config:
    host: str
    port: int = 63351
    zero_on_start: bool = False


@dataclass(frozen=True)
class ProbeConfig:
    device: str
    framing: str = "auto"
    byte_order: str = "auto"
    baudrate: int = 115200
    sensor: str = "fse103"  # or "loadcell"


@dataclass(frozen=True)
class RebiasConfig:
    samples: int = 500
    max_speed_m_s: float = 0.002
    tolerance_N: float = 2.0
    tolerance_Nm: float = 0.2
    timeout_s: float = 15.0


@dataclass(frozen=True)
class HardwareConfig:
    path: Path
    robot: RobotConfig
    ft150: FT150Config
    probe: ProbeConfig | None
    calibration: Path | None
    rebias: RebiasConfig
    estimator: EstimatorParams
    controller: ControllerParams
    log_dir: Path
    stale_stop_s: float = 0.25  # a stream silent this long ends the session (shorter: zero twist)
    preset: Preset | None = None  # the estimator's and the controller's preset

    def preset_changes(self) -> dict[str, object]:
        """Every value of the estimator's and the controller's parameters that differs from the
        preset (the rig file's sections, `--set`, the rig's sensors), as `block.leaf` names."""
        if self.preset is None:
            return {}
        return {
            f"{block}.{name}": value
            for block, params in (("estimator", self.estimator), ("controller", self.controller))
            for name, value in changed_from(self.preset.params[block], params).items()
        }


_TOP = (
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


def _section(w: Where, raw: Any, name: str, keys: tuple[str, ...]) -> dict[str, Any]:
    value = raw.get(name)
    return dict(w.mapping({} if value is None else value, keys, name))


def with_overrides(params: dict[str, Any], overrides: Sequence[str]) -> dict[str, Any]:
    """`params` (the estimator's and the controller's, by block name) with `--set` overrides
    (`estimator.x=v`, `controller.x=v`) applied in order: the rig file's, the rehearsal's and the
    replay's `--set`."""
    params = dict(params)
    for text in overrides:
        target, sep, value_text = text.partition("=")
        block, _, param_path = target.partition(".")
        if not sep or not param_path or block not in params:
            raise ConfigError(
                f"--set {text}: expected estimator.parameter=value or controller.parameter=value"
            )
        params[block] = override(
            params[block], param_path, parse_value(text, value_text), f"--set {block}"
        )
    return params


def load_config(
    path: str | Path,
    overrides: Sequence[str] = (),
    preset: str | Path | None = None,
    probe_sensor: str | None = None,
) -> HardwareConfig:
    """Read and check a rig's configuration; `overrides` are `estimator.x=v` / `controller.x=v`
    strings (`--set`), `preset` a preset's name or file (`--preset`; default: the file's `preset`,
    else `hoh_cosim.presets.DEFAULT_PRESET`), under the file's estimator and controller sections;
    `probe_sensor` (`--probe-sensor`: fse103, loadcell or none) the file's `probe.sensor`."""
    path = Path(path)
    w = Where(path)
    raw = w.mapping(read_yaml(path) or {}, _TOP, "")
    here = path.parent

    robot = _section(
        w,
        raw,
        "robot",
        (
            "host",
            "frequency_hz",
            "watchdog_hz",
            "acceleration",
            "sensor_rotvec_T",
            "realtime_priority",
        ),
    )
    if "host" not in robot:
        raise w.error("robot.host", "missing (the robot's address)")
    rotvec = robot.get("sensor_rotvec_T", list(_R_TS_DEFAULT))
    if not isinstance(rotvec, list) or len(rotvec) != 3:
        raise w.error("robot.sensor_rotvec_T", f"expected a list of 3 numbers, got {rotvec!r}")
    frequency = w.number(robot.get("frequency_hz", -1.0), "robot.frequency_hz")
    if frequency != -1.0 and not 1.0 <= frequency <= 1000.0:
        raise w.error("robot.frequency_hz", f"expected -1 or 1 to 1000 Hz, got {frequency}")
    robot_config = RobotConfig(
        host=w.string(robot["host"], "robot.host"),
        frequency_hz=frequency,
        watchdog_hz=w.number(robot.get("watchdog_hz", 20.0), "robot.watchdog_hz", positive=True),
        acceleration=w.number(robot.get("acceleration", 1.0), "robot.acceleration", positive=True),
        R_TS=rotvec_to_matrix(
            [w.number(x, f"robot.sensor_rotvec_T[{i + 1}]") for i, x in enumerate(rotvec)]
        ),
        realtime_priority=None
        if robot.get("realtime_priority") is None
        else w.integer(robot["realtime_priority"], "robot.realtime_priority", low=2, high=98),
    )

    ft = _section(w, raw, "ft150", ("host", "port", "zero_on_start"))
    ft_config = FT150Config(
        host=w.string(ft.get("host", robot_config.host), "ft150.host"),
        port=w.integer(ft.get("port", 63351), "ft150.port", low=1, high=65535),
        zero_on_start=w.boolean(ft.get("zero_on_start", False), "ft150.zero_on_start"),
    )

    probe_config = None
    if probe_sensor not in (None, *PROBE_SENSORS):
        raise ConfigError(
            f"--probe-sensor: expected one of {', '.join(PROBE_SENSORS)}, got {probe_sensor!r}"
        )
    if probe_sensor != "none" and ("probe" not in raw or raw["probe"] is not None):
        probe = _section(w, raw, "probe", ("sensor", "device", "framing", "byte_order", "baudrate"))
        if "device" not in probe:
            raise w.error("probe.device", "missing (or write `probe: null` for no probe sensor)")
        sensor = probe_sensor or w.string(
            probe.get("sensor", "fse103"), "probe.sensor", choices=PROBE_SENSORS[:2]
        )
        if sensor == "loadcell":
            for key in ("framing", "byte_order"):
                if key in probe:
                    raise w.error(f"probe.{key}", "is the FSE103's; the load cell has none")
        probe_config = ProbeConfig(
            sensor=sensor,
            device=w.string(probe["device"], "probe.device"),
            framing=w.string(
                probe.get("framing", "auto"), "probe.framing", choices=("auto", "seed18", "guide20")
            ),
            byte_order=w.string(
                probe.get("byte_order", "auto"),
                "probe.byte_order",
                choices=("auto", "little", "big"),
            ),
            baudrate=w.integer(probe.get("baudrate", 115200), "probe.baudrate", low=1),
        )

    calibration = None
    if raw.get("calibration") is not None:
        calibration = here / w.string(raw["calibration"], "calibration")

    rebias = _section(
        w, raw, "rebias", ("samples", "max_speed_m_s", "tolerance_N", "tolerance_Nm", "timeout_s")
    )
    rebias_config = RebiasConfig(
        samples=w.integer(rebias.get("samples", 500), "rebias.samples", low=1),
        max_speed_m_s=w.number(
            rebias.get("max_speed_m_s", 0.002), "rebias.max_speed_m_s", positive=True
        ),
        tolerance_N=w.number(rebias.get("tolerance_N", 2.0), "rebias.tolerance_N", positive=True),
        tolerance_Nm=w.number(
            rebias.get("tolerance_Nm", 0.2), "rebias.tolerance_Nm", positive=True
        ),
        timeout_s=w.number(rebias.get("timeout_s", 15.0), "rebias.timeout_s", positive=True),
    )

    from_file = preset is None
    if from_file:
        preset = raw.get("preset", DEFAULT_PRESET)
        if not isinstance(preset, str) or not preset:
            raise w.error("preset", f"expected a preset's name or a file's path, got {preset!r}")
        if preset.endswith((".yaml", ".yml")) or "/" in preset:
            preset = here / preset
    try:
        chosen = load_preset(preset)
    except ConfigError as exc:
        if not from_file:  # the command line's: no file to name
            raise
        raise ConfigError(f"{path}: {exc}") from None
    estimator_raw = raw.get("estimator") or {}
    if (
        probe_config is not None
        and probe_config.sensor == "loadcell"
        and isinstance(estimator_raw, dict)
    ):
        estimator_raw = estimator_defaults(estimator_raw)  # its mounting, rate, the wrist's help
    try:
        estimator = from_mapping(chosen.estimator, estimator_raw, "estimator")
        controller = from_mapping(chosen.controller, raw.get("controller") or {}, "controller")
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    log_dir = here / w.string(raw.get("log_dir", "sessions"), "log_dir")
    params = with_overrides({"estimator": estimator, "controller": controller}, overrides)
    try:
        sensors = SensorSetup.shared(params["estimator"], params["controller"])
        if probe_config is None:  # no probe sensor: no compensation, fixture or contact limits
            sensors = dataclasses.replace(sensors, use_probe=False)
        # the blocks' parameters are checked again as they are rebuilt with the rig's sensors
        params["estimator"], params["controller"] = sensors.apply(
            params["estimator"], params["controller"]
        )
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    return HardwareConfig(
        path,
        robot_config,
        ft_config,
        probe_config,
        calibration,
        rebias_config,
        params["estimator"],
        params["controller"],
        log_dir,
        w.number(raw.get("stale_stop_s", 0.25), "stale_stop_s", positive=True),
        chosen,
    )
