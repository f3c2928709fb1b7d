"""`hoh-cosim hw check --rehearse`: the commissioning check against the rehearsal world.

The same `hardware.check_run.record_check` and `hardware.check.judge` as on a rig, with the real
drivers on a loopback socket and a pseudo-terminal, against a world (`rehearsal.world`) in which the
operator's hand is off the handle and pushes the probe's tip three times when the check says so
(`WorldSetup.probe_check_s`, `RehearsalWorld.start_task`), and a fault of `rehearsal.planted` may
be planted. The rig's claims are the rehearsal's rig file's (`rehearse.rehearsal_config`: the FT-150
at 200 Hz, the FSE103 at 50 Hz, R_SP of eq. 2) and the tool the world's truth, as a perfect
`hw calibrate` would find it.

`tally` runs many: healthy ones with consecutive seeds and each planted fault once, and counts the
false alarms and the faults caught with their cause named.
"""

from __future__ import annotations

import contextlib
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.hardware.check import PROBE_SENSORS, Claims, SensorVerdict, judge
from hoh_cosim.hardware.check_run import REHEARSAL_PLAN, CheckPlan, RecordingMailbox, record_check
from hoh_cosim.hardware.ft150 import FT150Stream
from hoh_cosim.hardware.probe_port import probe_port
from hoh_cosim.hardware.robot import Robot, RtdeRobot
from hoh_cosim.rehearsal.planted import PLANTED, planted_world
from hoh_cosim.rehearsal.rehearse import UR_SERIES, rehearsal_config, truth_calibration
from hoh_cosim.rehearsal.world import RehearsalWorld, WorldSetup

__all__ = ["PUSHES_S", "CheckOutcome", "Tally", "rehearse_check", "tally"]

PUSHES_S = 6.5
"""[s] The world's probe check: the hand pushes from 0.5 s after the check's call, three 2 s
pushes (`plant_models.operator`'s push_s), within the plan's 7 s push window."""


@dataclass
class CheckOutcome:
    verdicts: list[SensorVerdict]
    about: dict[str, Any]


def rehearse_check(
    probe_sensor: str = "fse103",
    faults: Sequence[str] = (),
    seed: int = 1,
    *,
    plan: CheckPlan = REHEARSAL_PLAN,
    ur_host: str | None = None,
    robot_rate_hz: float = 500.0,
    announce: Callable[[str], None] = lambda message: None,
) -> CheckOutcome:
    """One check against a world with `faults` planted (none: healthy), seeded by `seed`."""
    if probe_sensor not in PROBE_SENSORS:
        raise ConfigError(
            f"--probe-sensor: expected one of {', '.join(PROBE_SENSORS)}, got {probe_sensor!r}"
        )
    planted, changes = planted_world(faults, probe_sensor)
    setup = WorldSetup(
        robot_rate_hz=robot_rate_hz,
        task="off",
        task_start_s=None,
        probe_check_s=PUSHES_S if probe_sensor != "none" else 0.0,
        seed=seed,
        probe_sensor=probe_sensor,
        hand_seed=seed,  # the pushes differ from seed to seed, as the sensors' noise
        planted=planted,
        **changes,
    )
    started = time.monotonic()
    with RehearsalWorld(setup) as world, tempfile.TemporaryDirectory() as log_dir:
        config = rehearsal_config(world, Path(log_dir))
        claims = Claims(
            ft_rate_hz=1.0 / config.estimator.ft_packet_period_s,
            probe_rate_hz=1.0 / config.estimator.probe_packet_period_s,
            R_SP=config.estimator.R_SP,
            tool=truth_calibration(world.truth).tool,
        )
        ft = FT150Stream(config.ft150.host, config.ft150.port, mailbox=RecordingMailbox())
        probe = (
            None
            if config.probe is None
            else probe_port(config.probe, reconnect=False, mailbox=RecordingMailbox())
        )
        with contextlib.ExitStack() as stack:
            robot: Robot = world.robot()
            if ur_host is not None:
                from hoh_cosim.rehearsal.ur_controller import UrController

                try:
                    series = UR_SERIES[robot_rate_hz]
                    stack.enter_context(UrController(world, ur_host, series=series))
                except (RuntimeError, OSError, KeyError) as exc:
                    raise RunError(f"--ur-emulator {ur_host}: {exc}") from None
                robot = RtdeRobot(ur_host, watchdog_hz=setup.watchdog_hz)
            record = record_check(
                robot,
                ft,
                probe,
                R_TS=config.robot.R_TS,
                plan=plan,
                push=world.start_task,
                acceleration=config.robot.acceleration,
                realtime_priority=config.robot.realtime_priority,
                announce=announce,
            )
    verdicts = judge(record, claims, probe_sensor)
    about = {
        "kind": "rehearsal",
        "probe_sensor": probe_sensor,
        "faults": list(faults),
        "seed": seed,
        "duration_s": round(time.monotonic() - started, 2),
    }
    return CheckOutcome(verdicts, about)


@dataclass
class Tally:
    healthy: int = 0
    false_alarms: list[tuple[int, str]] = field(default_factory=list)  # (seed, line)
    faults: int = 0
    caught: list[str] = field(default_factory=list)
    missed: list[tuple[str, str]] = field(default_factory=list)  # (fault, why)
    errors: list[tuple[str, str]] = field(default_factory=list)  # (run, why): no verdict
    reports: list[dict[str, Any]] = field(default_factory=list)
    wall_s: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.false_alarms and not self.missed and not self.errors

    def summary(self) -> str:
        return (
            f"{self.faults - len(self.missed)}/{self.faults} planted faults caught, "
            f"{len(self.false_alarms)} false alarms in {self.healthy} healthy rehearsals, "
            f"{len(self.errors)} checks ended without a verdict, {self.wall_s:.0f} s"
        )


def caught(outcome: CheckOutcome, fault: str) -> str | None:
    """None when the fault's sensor failed on the fault's finding; otherwise why not."""
    entry = PLANTED[fault]
    verdict = next((v for v in outcome.verdicts if v.sensor == entry.sensor), None)
    if verdict is None:
        return f"no verdict for {entry.sensor}"
    if verdict.ok:
        return f"{entry.sensor} passed: {verdict.line()}"
    failed = {f.what for f in verdict.findings if not f.ok}
    if entry.finding not in failed:
        return f"{entry.sensor} failed on {', '.join(sorted(failed))}, not {entry.finding}"
    return None


def tally(
    runs: int,
    seed: int,
    probe_sensor: str = "fse103",
    *,
    faults: bool = True,
    tell: Callable[[str], None] = lambda line: None,
) -> Tally:
    """`runs` healthy checks with seeds `seed`, `seed + 1`, ..., then (with `faults`) each planted
    fault this probe sensor can show, once, with seed `seed`."""
    out = Tally()
    started = time.monotonic()
    for k in range(runs):
        try:
            outcome = rehearse_check(probe_sensor, (), seed + k)
        except RunError as exc:  # the check itself failed (the robot, a stream): no verdict
            out.errors.append((f"healthy seed {seed + k}", str(exc)))
            tell(f"healthy seed {seed + k}: ERROR {exc}")
            continue
        out.healthy += 1
        out.reports.append({**outcome.about, "verdicts": [v.as_dict() for v in outcome.verdicts]})
        bad = [v.line() for v in outcome.verdicts if not v.ok]
        if bad:
            out.false_alarms.append((seed + k, " | ".join(bad)))
        tell(f"healthy seed {seed + k}: {'FALSE ALARM ' + ' | '.join(bad) if bad else 'ok'}")
    if faults:
        for name, entry in PLANTED.items():
            if entry.needs_probe not in (None, probe_sensor):
                continue
            try:
                outcome = rehearse_check(probe_sensor, (name,), seed)
            except ConfigError as exc:  # a fault this build cannot plant (the load cell's)
                tell(f"fault {name}: not planted ({exc})")
                continue
            except RunError as exc:
                out.errors.append((f"fault {name}", str(exc)))
                tell(f"fault {name}: ERROR {exc}")
                continue
            out.faults += 1
            out.reports.append(
                {**outcome.about, "verdicts": [v.as_dict() for v in outcome.verdicts]}
            )
            why = caught(outcome, name)
            if why is None:
                out.caught.append(name)
            else:
                out.missed.append((name, why))
            line = next(v.line() for v in outcome.verdicts if v.sensor == entry.sensor)
            tell(f"fault {name}: {'caught' if why is None else 'MISSED ' + why}: {line}")
    out.wall_s = time.monotonic() - started
    return out
