"""A rehearsal: the real runner, real drivers and real session log against emulated devices.

`hoh_cosim.rehearsal.world` serves an FT-150 stream on loopback and an FSE103 on a pseudo-terminal from
a world process that moves the simulated arm in real time; the runner connects to them exactly as to
a rig. The calibration is the world's truth (the tool and the FT-150's offset), as a perfect
`hoh-cosim hw calibrate` would find it. What to rehearse is one record, `Rehearsal`:

    rehearse(Rehearsal(seconds=20.0, log_path=Path("sessions/r.mcap"), task="line"))
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.control.controller import ControllerParams
from hoh_cosim.control.cycle import SensorSetup
from hoh_cosim.control.estimator import EstimatorParams
from hoh_cosim.control.gravity import GravityCalibration
from hoh_cosim.control.loadcell import estimator_defaults
from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.hardware.config import (
    FT150Config,
    HardwareConfig,
    ProbeConfig,
    RebiasConfig,
    RobotConfig,
)
from hoh_cosim.hardware.feed import CycleObserver
from hoh_cosim.hardware.fse103 import FSE103Port
from hoh_cosim.hardware.ft150 import FT150Stream
from hoh_cosim.hardware.probe_port import probe_port
from hoh_cosim.hardware.robot import Robot, RtdeRobot
from hoh_cosim.hardware.runner import Runner, SessionResult
from hoh_cosim.hardware.session_log import SessionLog
from hoh_cosim.params import from_mapping
from hoh_cosim.presets import Preset
from hoh_cosim.rehearsal.priorities import LOOP_PRIORITY
from hoh_cosim.rehearsal.ur_controller import UrController
from hoh_cosim.rehearsal.world import Fault, RehearsalWorld, WorldSetup
from plant_models.loadcell import LoadCellParams

__all__ = [
    "Rehearsal",
    "RehearsalResult",
    "rehearsal_config",
    "rehearse",
    "truth_calibration",
    "write_truth_calibration",
]

# the UR series a robot rate stands for, when the arm sits behind the emulated UR controller
UR_SERIES = {500.0: "e", 125.0: "cb3"}


def truth_calibration(truth: dict) -> GravityCalibration:
    """The calibration a perfect identification would give in the rehearsal world."""
    bias = np.asarray(truth["bias"], dtype=float)
    nan3 = np.full(3, np.nan)
    return GravityCalibration(
        mass_kg=float(truth["mass_kg"]),
        com_m=np.asarray(truth["com_m"], dtype=float),
        force_bias_N=bias[:3],
        torque_bias_Nm=bias[3:],
        mass_se_kg=0.0,
        com_se_m=np.zeros(3),
        force_bias_se_N=np.zeros(3),
        torque_bias_se_Nm=np.zeros(3),
        condition_number=np.nan,
        n_poses=0,
        gravity_B=np.asarray(truth["gravity_B"], dtype=float),
        residual_rms_before=np.concatenate([nan3, nan3]),
        residual_max_before=np.concatenate([nan3, nan3]),
        residual_rms_after=np.concatenate([nan3, nan3]),
        residual_max_after=np.concatenate([nan3, nan3]),
    )


def write_truth_calibration(truth: dict, path: Path) -> None:
    """`truth_calibration` as a perfect `hoh-cosim hw calibrate` would write it for a rig file: a
    file holds a pose count, a condition number and residuals, here the seed's 32 poses, 1 and 0."""
    from hoh_cosim.calibration import write_calibration

    zeros = np.zeros(6)
    calibration = dataclasses.replace(
        truth_calibration(truth),
        n_poses=32,
        condition_number=1.0,
        residual_rms_before=zeros,
        residual_max_before=zeros,
        residual_rms_after=zeros,
        residual_max_after=zeros,
    )
    write_calibration(path, calibration)


def rehearsal_config(
    world: RehearsalWorld,
    log_dir: Path,
    *,
    rebias_samples: int = 500,
    estimator: EstimatorParams | None = None,
    controller: ControllerParams | None = None,
    realtime_priority: int | None = LOOP_PRIORITY,
    preset: Preset | None = None,
) -> HardwareConfig:
    setup = world.setup
    probe = None
    if setup.probe_sensor != "none":
        probe = ProbeConfig(device=world.pty_name, sensor=setup.probe_sensor)
    estimator, controller = _with_probe_sensor(
        setup.probe_sensor, estimator or EstimatorParams(), controller or ControllerParams()
    )
    return HardwareConfig(
        path=Path("<rehearsal>"),
        robot=RobotConfig(
            host="rehearsal",
            frequency_hz=setup.robot_rate_hz,
            watchdog_hz=setup.watchdog_hz,
            realtime_priority=realtime_priority,
        ),
        ft150=FT150Config(host="127.0.0.1", port=world.ft_port),
        probe=probe,
        calibration=None,
        rebias=RebiasConfig(samples=rebias_samples),
        estimator=estimator,
        controller=controller,
        log_dir=log_dir,
        preset=preset,
    )


def _with_probe_sensor(
    sensor: str, estimator: EstimatorParams, controller: ControllerParams
) -> tuple[EstimatorParams, ControllerParams]:
    """The blocks' parameters for the world's probe sensor. A load cell: its mounting and line
    period are the world's (`estimator_defaults`), and the contact across the probe's axis comes
    from the wrist unless the parameters already take it from there. None: no probe sensor."""
    if sensor == "loadcell":
        defaults = estimator_defaults({})
        if estimator.probe_correction.across_from_wrist_s > 0.0:
            del defaults["probe_correction"]
        estimator = from_mapping(estimator, defaults, "estimator")
    sensors = SensorSetup.of(estimator)
    if sensor == "none":
        sensors = dataclasses.replace(sensors, use_probe=False)
    return sensors.apply(estimator, controller)


@dataclass(frozen=True)
class Rehearsal:
    """What to rehearse: one session of `seconds`, logged to `log_path`, against a world set up so.

    With `ur_host`, the robot is the world's arm behind the loopback UR controller
    (`hoh_cosim.rehearsal.ur_controller`) at that address, driven through ur-rtde by the real
    `RtdeRobot`, as on a rig; otherwise the runner reaches the arm through shared memory."""

    seconds: float
    log_path: Path
    task: str = "circle"
    robot_rate_hz: float = 500.0
    faults: tuple[Fault, ...] = ()
    rebias_samples: int = 500
    task_start_s: float | None = None  # None: once the runner says its rebias is done
    phantom_below_m: float | None = None
    breathing_m: float = 0.0  # the phantom breathes this deep (WorldSetup)
    let_go_s: float = 0.0  # the hand lets go this long after it took the handle (0: never)
    retake_s: float = 0.0  # ... and takes it again then (0: never)
    away_m: float = 0.0  # the patient moves this far away from the probe (WorldSetup; 0: never)
    away_s: float = 0.0  # ... this long after the hand took the handle
    away_time_s: float = 0.3  # ... within this long
    controller: ControllerParams | None = None
    estimator: EstimatorParams | None = None
    seed: int = 1
    realtime_priority: int | None = LOOP_PRIORITY  # None: the default priority
    ur_host: str | None = None
    preset: Preset | None = None  # what `estimator` and `controller` came from, for the log
    probe_sensor: str = "fse103"  # or loadcell, or none (WorldSetup)
    loadcell: LoadCellParams = field(default_factory=LoadCellParams)  # its faults (WorldSetup)

    def __post_init__(self) -> None:
        object.__setattr__(self, "faults", tuple(self.faults))
        if self.ur_host is not None and self.robot_rate_hz not in UR_SERIES:
            raise ConfigError(
                f"--rate: a UR controller runs at 125 or 500 Hz, got {self.robot_rate_hz:g}"
            )


@dataclass
class RehearsalResult:
    session: SessionResult
    log_path: Path
    probe_framing: str | None
    probe_byte_order: str | None


def rehearse(
    setup: Rehearsal,
    *,
    announce: Callable[[str], None] = lambda message: None,
    observer: CycleObserver | None = None,
) -> RehearsalResult:
    """Start the world, run one session against it for `setup.seconds`, stop everything;
    `observer` is offered the runner's cycles (the live view's feed)."""
    # without a start time, the hand takes the handle once the runner says its rebias is done
    # (a start time guessed from the rebias's length came too early on a busy machine)
    world_setup = WorldSetup(
        robot_rate_hz=setup.robot_rate_hz,
        task=setup.task,
        task_start_s=setup.task_start_s,
        phantom_below_m=setup.phantom_below_m,
        breathing_m=setup.breathing_m,
        let_go_s=setup.let_go_s,
        retake_s=setup.retake_s,
        seed=setup.seed,
        faults=setup.faults,
        probe_check_s=_probe_check_s(setup.estimator),
        away_m=setup.away_m,
        away_s=setup.away_s,
        away_time_s=setup.away_time_s,
        probe_sensor=setup.probe_sensor,
        loadcell=setup.loadcell,
    )
    announce("starting the rehearsal world")
    with RehearsalWorld(world_setup) as world:
        config = rehearsal_config(
            world,
            setup.log_path.parent,
            rebias_samples=setup.rebias_samples,
            estimator=setup.estimator,
            controller=setup.controller,
            realtime_priority=setup.realtime_priority,
            preset=setup.preset,
        )
        calibration = truth_calibration(world.truth)
        ft = FT150Stream(config.ft150.host, config.ft150.port)
        probe = None if config.probe is None else probe_port(config.probe, reconnect=False)
        with contextlib.ExitStack() as stack:
            robot: Robot = world.robot()
            if setup.ur_host is not None:
                series = UR_SERIES[setup.robot_rate_hz]
                try:
                    stack.enter_context(UrController(world, setup.ur_host, series=series))
                except (RuntimeError, OSError) as exc:
                    raise RunError(f"--ur-emulator {setup.ur_host}: {exc}") from None
                robot = RtdeRobot(setup.ur_host, watchdog_hz=world_setup.watchdog_hz)
                announce(f"UR controller emulated on {setup.ur_host} (ur-rtde)")
            log = SessionLog(setup.log_path, _metadata(config, world_setup)).start()

            def tell(message: str) -> None:
                if message.startswith("rebias done"):
                    world.start_task()
                announce(message)

            runner = Runner(
                config, robot, ft, probe, calibration, log, announce=tell, observer=observer
            )
            session = runner.run(setup.seconds)
    framing = byte_order = None
    if isinstance(probe, FSE103Port):
        framing, byte_order = probe.parser.framing, probe.parser.byte_order
    return RehearsalResult(session, setup.log_path, framing, byte_order)


def _probe_check_s(estimator: EstimatorParams | None) -> float:
    """How long the runner's probe check lasts, during which the world's hand pushes the tip."""
    if estimator is None or estimator.probe_correction.kind != "online":
        return 0.0
    return estimator.probe_correction.check_s


def _metadata(config: HardwareConfig, setup: WorldSetup) -> dict:
    return {
        "kind": "rehearsal",
        "robot": config.robot.host,
        "period_s": 1.0 / setup.robot_rate_hz,
        "R_TS": config.robot.R_TS.tolist(),
        "world": {f.name: _world_value(setup, f.name) for f in dataclasses.fields(setup)},
    }


def _world_value(setup: WorldSetup, name: str) -> Any:
    """A world parameter as the log's metadata keeps it: plain values, the faults as pairs, the
    load cell's parameters and the planted faults as mappings."""
    if name == "faults":
        return [(f.at_s, f.kind) for f in setup.faults]
    value = getattr(setup, name)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    return value
