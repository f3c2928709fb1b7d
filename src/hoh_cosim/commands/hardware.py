"""The hardware commands of `hoh-cosim`:

    hoh-cosim hw run CONFIG.yaml [--seconds S] [--log FILE] [--preset NAME|FILE]
                                 [--set block.parameter=value ...]
                                 [--view] [--record-view FILE.rrd] [--view-port PORT]
    hoh-cosim hw calibrate CONFIG.yaml [--out FILE] [--samples N] [--tilts N] [--directions N]
    hoh-cosim hw sensors [--ft HOST[:PORT]] [--probe DEVICE] [--seconds S] [--json]
    hoh-cosim hw rehearse [--seconds S] [--task TASK] [--rate HZ] [--fault KIND@SECONDS ...]
                          [--breathing MM] [--let-go S+D] [--away MM@S[/D]] [--preset NAME|FILE]
                          [--view] [--record-view FILE.rrd] [--view-port PORT]
    hoh-cosim hw emulate [--host 127.0.0.1] [--series e|cb3] [--seconds N] [--allow-remote]
    hoh-cosim hw check [CONFIG.yaml] [--rehearse] [--probe-sensor fse103|loadcell|none]
                       [--fault NAME ...] [--seed S] [--repeat N] [--override SENSOR ...] [--out FILE]
    hoh-cosim hw campaign [--runs N] [--seed S] [--workers W] [--out DIR] [--kinds K,K,...]
    hoh-cosim replay LOG.mcap [--preset NAME|FILE] [--set block.parameter=value ...] [--out DIR]
                              [--view] [--record-view FILE.rrd] [--view-port PORT]

Exit status as everywhere: 0 done, 2 the input is wrong, 1 the session ended on a fault.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import signal
import sys
from pathlib import Path
from typing import Any

from hoh_cosim.commands import add_set_option, add_view_options, check_view_options, linger
from hoh_cosim.errors import ConfigError, RunError, io_failure
from hoh_cosim.rehearsal.faults import CAMPAIGN_KINDS, FAULTS, Fault
from hoh_cosim.rehearsal.priorities import LOOP_PRIORITY
from hoh_cosim.results import check_out_dir, check_writable, replace_dir
from plant_models.tasks import CONTACT_TASKS, TASKS

__all__ = ["add_commands", "run_command"]


def _endpoint(text: str) -> tuple[str, int]:
    host, _, port = text.partition(":")
    if not host:
        raise argparse.ArgumentTypeError(f"expected HOST or HOST:PORT, got {text!r}")
    if not port:
        return host, 63351
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port 1 to 65535, got {port!r}")
    return host, int(port)


def _fault(text: str) -> Fault:
    kind, _, when = text.partition("@")
    at, _, duration = when.partition("+")
    try:
        at_s, duration_s = float(at), float(duration or 0.0)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected KIND@SECONDS or KIND@SECONDS+DURATION, got {text!r}"
        ) from None
    if kind not in FAULTS:
        raise argparse.ArgumentTypeError(f"expected one of {', '.join(FAULTS)}, got {kind!r}")
    if not (math.isfinite(at_s) and math.isfinite(duration_s) and duration_s >= 0.0):
        raise argparse.ArgumentTypeError(
            f"expected finite seconds and a duration >= 0, got {text!r}"
        )
    return Fault(at_s, kind, duration_s)


def _let_go(text: str) -> tuple[float, float]:
    """S+D: the hand lets go S s after it took the handle, and takes it again D s later."""
    at, plus, duration = text.partition("+")
    try:
        at_s, off_s = float(at), float(duration)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected SECONDS+DURATION, got {text!r}") from None
    if not (plus and math.isfinite(at_s + off_s) and at_s > 0.0 and off_s > 0.0):
        raise argparse.ArgumentTypeError(f"expected seconds > 0 and a duration > 0, got {text!r}")
    return at_s, at_s + off_s


def _away(text: str) -> tuple[float, float, float]:
    """MM@S[/D]: the patient moves MM mm away S s after the hand took the handle, within D s."""
    size, at, rest = text.partition("@")
    when, _, within = rest.partition("/")
    try:
        mm, at_s, time_s = float(size), float(when), float(within or 0.3)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected MM@SECONDS or MM@SECONDS/DURATION, got {text!r}"
        ) from None
    if not (
        at
        and math.isfinite(mm + at_s + time_s)
        and 0.0 < mm <= 100.0
        and at_s > 0.0
        and time_s > 0.0
    ):
        raise argparse.ArgumentTypeError(
            f"expected 0 to 100 mm, seconds > 0 and a duration > 0, got {text!r}"
        )
    return 1e-3 * mm, at_s, time_s


def _rt_priority(text: str) -> int | None:
    """A SCHED_FIFO priority for a loop, 0 for none."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value == 0:
        return None
    if not 2 <= value <= 98:  # its helpers run one below; the kernel's own threads at 99
        raise argparse.ArgumentTypeError(f"expected 0 (none) or 2 to 98, got {text!r}")
    return value


def _add_rt_priority(parser: argparse.ArgumentParser, loop: str) -> None:
    parser.add_argument(
        "--rt-priority",
        type=_rt_priority,
        default=LOOP_PRIORITY,
        metavar="P",
        help=f"SCHED_FIFO priority for {loop}, as a rig's runs, 0 for none (Linux; without the "
        f"right, a note and the default priority; default: {LOOP_PRIORITY})",
    )


def _add_config(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "config", metavar="CONFIG.yaml", help="the rig's configuration (hoh_cosim.hardware.config)"
    )


def _add_probe_sensor(parser: argparse.ArgumentParser, default: str) -> None:
    from hoh_cosim.control.sensors import PROBE_SENSORS

    parser.add_argument(
        "--probe-sensor",
        choices=PROBE_SENSORS,
        default=None,
        help="the probe sensor: the Variense FSE103, the Honeywell Model 31 load cell on its "
        f"Arduino, or none (default: {default})",
    )


def _loadcell_setting(text: str) -> tuple[str, str]:
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(
            f"expected PARAM=VALUE, e.g. saturated=true or zero_drift_N_per_min=0.5, got {text!r}"
        )
    return name, value


def _add_loadcell_settings(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--loadcell",
        dest="loadcell",
        action="append",
        default=[],
        type=_loadcell_setting,
        metavar="PARAM=VALUE",
        help="a parameter of the emulated load cell (with --probe-sensor loadcell; repeatable), "
        "its faults among them: saturated=true (the seed's cell), open_circuit=true, "
        "zero_drift_N_per_min=RATE (default: a sound cell)",
    )


def _add_preset(parser: argparse.ArgumentParser, default: str) -> None:
    from hoh_cosim.commands.cosim import add_preset_option

    add_preset_option(parser, default)


def _add_block_overrides(parser: argparse.ArgumentParser) -> None:
    add_set_option(
        parser,
        "estimator.x=v or controller.x=v (repeatable; default: the config's or the log's "
        "parameters)",
        metavar="B.P=V",
    )


def add_commands(sub: Any) -> None:
    """The `hw` and `replay` subcommands, on the main parser's subparsers."""
    hw = sub.add_parser(
        "hw",
        help="run, calibrate, diagnose or rehearse on the robot",
        description="Commands for the real UR5, its FT-150 and its FSE103.",
    )
    hw_sub = hw.add_subparsers(dest="hw_command", metavar="HW_COMMAND", parser_class=type(hw))

    run = hw_sub.add_parser(
        "run",
        help="a hand-guiding session",
        description="Rebias, then guide the robot by hand until the time is "
        "up, Ctrl-C, or a fault; every cycle is logged (MCAP).",
    )
    _add_config(run)
    run.add_argument(
        "--seconds",
        type=float,
        metavar="S",
        help="end after S seconds (default: at Ctrl-C or a fault)",
    )
    run.add_argument(
        "--log",
        metavar="FILE",
        help="the session log (default: in the config's log_dir, named by date and time)",
    )
    _add_preset(run, "the config's preset, else " + _default_preset())
    _add_probe_sensor(run, "the config's probe.sensor, fse103 if it names none")
    _add_block_overrides(run)
    add_view_options(run, "the session")

    cal = hw_sub.add_parser(
        "calibrate",
        help="the gravity calibration on the robot",
        description="Move through static poses, average the FT-150 at each, "
        "identify the tool and write calibration.json (and poses.csv).",
    )
    _add_config(cal)
    cal.add_argument(
        "--out",
        metavar="FILE",
        help="where to write the calibration (default: the config's calibration file)",
    )
    cal.add_argument(
        "--samples",
        type=int,
        default=1000,
        metavar="N",
        help="samples averaged per pose (default 1000, the seed's)",
    )
    cal.add_argument(
        "--tilts", type=int, default=4, metavar="N", help="tilts from 15 to 60 degrees (default 4)"
    )
    cal.add_argument(
        "--directions",
        type=int,
        default=8,
        metavar="N",
        help="horizontal directions per tilt (default 8)",
    )

    sensors = hw_sub.add_parser(
        "sensors",
        help="read the sensor streams and describe them",
        description="Read the FT-150 stream and/or the FSE103 for a while "
        "and print rate, mean, standard deviation and frame counts.",
    )
    sensors.add_argument(
        "--ft",
        type=_endpoint,
        metavar="HOST[:PORT]",
        help="the FT-150 stream (port 63351 by default)",
    )
    sensors.add_argument(
        "--probe", metavar="DEVICE", help="the FSE103's serial device (default: none)"
    )
    sensors.add_argument(
        "--framing",
        default="auto",
        choices=("auto", "seed18", "guide20"),
        help="the FSE103's frame layout: the seed's 18 bytes, the guide's 20, or found from the "
        "bytes (default: auto)",
    )
    sensors.add_argument(
        "--byte-order",
        default="auto",
        choices=("auto", "little", "big"),
        help="the FSE103's byte order (default: auto, found from the bytes)",
    )
    sensors.add_argument(
        "--seconds",
        type=float,
        default=5.0,
        metavar="S",
        help="how long to read the streams (default: 5); ends at once if every stream fails",
    )
    sensors.add_argument("--json", action="store_true", help="one JSON object on stdout")

    rehearse = hw_sub.add_parser(
        "rehearse",
        help="the real runner against emulated devices",
        description="Run a session with the real runner, drivers and "
        "log against an emulated UR5, FT-150 stream and FSE103.",
    )
    rehearse.add_argument(
        "--seconds",
        type=float,
        default=20.0,
        metavar="S",
        help="the session's length after the rebias (default: 20)",
    )
    rehearse.add_argument(
        "--task",
        choices=TASKS,
        default="circle",
        help="what the emulated operator's hand does (default: circle; press and scan put a "
        "phantom 3 cm under the probe)",
    )
    rehearse.add_argument(
        "--breathing",
        type=float,
        default=0.0,
        metavar="MM",
        help="the phantom breathes this deep, 15 breaths a minute (a contact task; default: 0)",
    )
    rehearse.add_argument(
        "--let-go",
        type=_let_go,
        default=None,
        metavar="S+D",
        help="the hand lets go of the handle S s after it took it and takes it again D s later, "
        "e.g. 6+8: with --set controller.hold.enabled=true the robot holds the contact force "
        "meanwhile (hold-on-release; default: the hand keeps hold)",
    )
    rehearse.add_argument(
        "--away",
        type=_away,
        default=None,
        metavar="MM@S[/D]",
        help="the patient moves MM mm away from the probe S s after the hand took the handle, "
        "within D s (default 0.3), e.g. 15@12: with --preset clinical the robot brings the "
        "contact back (a contact task)",
    )
    rehearse.add_argument(
        "--rate",
        type=float,
        default=500.0,
        choices=(125.0, 500.0),
        help="the robot's rate in Hz: 125 (CB3) or 500 (e-series) (default: 500)",
    )
    rehearse.add_argument(
        "--fault",
        dest="faults",
        action="append",
        default=[],
        type=_fault,
        metavar="KIND@S[+D]",
        help=f"schedule a fault at S s of the world's clock, for D s (default: for good), e.g. "
        f"ft_stall@12 or ft_stall@12+0.1 (repeatable); KIND: {', '.join(FAULTS)}",
    )
    rehearse.add_argument(
        "--log",
        metavar="FILE",
        default=None,
        help="the session log (default: sessions/rehearsal-<time>.mcap)",
    )
    rehearse.add_argument(
        "--rebias-samples",
        type=int,
        default=500,
        metavar="N",
        help="FT-150 samples averaged by the rebias (default: 500, 2.5 s at 200 Hz)",
    )
    rehearse.add_argument(
        "--ur-emulator",
        metavar="HOST",
        default=None,
        help=(
            "drive the arm through ur-rtde and a loopback UR controller listening on HOST "
            "(e.g. 127.0.0.1; ports 29999, 30003, 30004) instead of shared memory (the default)"
        ),
    )
    _add_rt_priority(rehearse, "the loop")
    add_view_options(rehearse, "the session")
    _add_preset(rehearse, _default_preset())
    _add_probe_sensor(rehearse, "fse103")
    _add_loadcell_settings(rehearse)
    rehearse.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="BLOCK.PARAM=VALUE",
        help=(
            "override an estimator or controller parameter, as in a rig file (repeatable), e.g. "
            "controller.release.enabled=true (default: the preset's values)"
        ),
    )

    _add_check(hw_sub)

    campaign = hw_sub.add_parser(
        "campaign",
        help="many short rehearsals through hw run, each with random faults, invariants checked",
        description="Run N short sessions of `hoh-cosim hw run` against the emulated UR controller, "
        "FT-150 and FSE103, each with one to three faults drawn at random (kind, time, duration) "
        "from the run's seed (the campaign's seed plus the run's number), and check on each that "
        "a fault that calls for a stop stops the arm in time, the cause is named, the log is "
        "complete and valid, and nothing is left running. Writes campaign.csv and summary.json, "
        "prints a table per fault kind. A failing run is re-run alone with --runs 1 --seed "
        "<its seed>. Exit status 1 when any run broke an invariant. Needs the hardware extra.",
    )
    campaign.add_argument(
        "--runs", type=int, default=20, metavar="N", help="how many runs (default: 20)"
    )
    campaign.add_argument(
        "--seed", type=int, default=1, metavar="S", help="the first run's seed (default: 1)"
    )
    campaign.add_argument(
        "--workers",
        type=int,
        default=1,
        metavar="W",
        help="runs at once, each with its own world, controller and runner; a run takes about "
        "a core, so at most half the cores (default: 1)",
    )
    campaign.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help="where campaign.csv, summary.json and each run's files go "
        "(default: runs/campaign-<time>)",
    )
    campaign.add_argument(
        "--kinds",
        default=None,
        metavar="K,K,...",
        help=f"draw faults of these kinds only (default: all: {', '.join(CAMPAIGN_KINDS)})",
    )
    _add_rt_priority(campaign, "each runner's loop")

    emulate = hw_sub.add_parser(
        "emulate",
        help="the emulated UR controller, FT-150 and FSE103 alone, for other clients",
        description="Start the rehearsal's emulated devices on their own: a UR controller "
        "(dashboard 29999, script 30003, RTDE 30004) driving the simulated arm, the FT-150 stream "
        "and the FSE103 on a pseudo-terminal, and print where they are, so that your own scripts, "
        "ur-rtde, UR's RTDE client or a ROS driver can be pointed at them. Ends after --seconds "
        "or on Ctrl-C.",
    )
    emulate.add_argument(
        "--host",
        default="127.0.0.1",
        help="the address the controller and the FT-150 stream listen on (default: 127.0.0.1; "
        "a non-loopback address needs --allow-remote)",
    )
    emulate.add_argument(
        "--series",
        choices=("e", "cb3"),
        default="e",
        help="the controller generation: e (e-series, 500 Hz) or cb3 (125 Hz) (default: e)",
    )
    emulate.add_argument(
        "--seconds",
        type=float,
        default=None,
        metavar="S",
        help="stop after S seconds (default: run until Ctrl-C)",
    )
    emulate.add_argument(
        "--ft-port",
        type=int,
        default=63351,
        metavar="PORT",
        help="the FT-150 stream's port (default: 63351, the URCap's; 0: any free port)",
    )
    emulate.add_argument(
        "--task",
        choices=TASKS,
        default="off",
        help="what the emulated operator's hand does from --task-start (default: off, nobody "
        "touches the handle)",
    )
    _add_probe_sensor(emulate, "fse103")
    _add_loadcell_settings(emulate)
    emulate.add_argument(
        "--task-start",
        type=float,
        default=5.0,
        metavar="S",
        help="when the hand takes the handle, in seconds of the world's clock (default: 5)",
    )
    emulate.add_argument(
        "--allow-remote",
        action="store_true",
        help="listen on a non-loopback --host: anyone on that network can then move the "
        "emulated arm (never a real one)",
    )

    rep = sub.add_parser(
        "replay",
        help="re-run the estimator and controller on a session log",
        description="Feed a session log's recorded inputs to the estimator and "
        "controller with other settings; plot recorded against replayed.",
    )
    rep.add_argument("log", metavar="LOG.mcap", help="a session log of hw run or hw rehearse")
    _add_preset(rep, "the session's own parameters")
    _add_block_overrides(rep)
    rep.add_argument(
        "--out", metavar="DIR", help="the results directory (default: runs/replay-<log name>)"
    )
    add_view_options(rep, "the session with the logged and the recomputed commands", live=False)


def _add_check(hw_sub: Any) -> None:
    check = hw_sub.add_parser(
        "check",
        help="commission the sensors before a session (about 45 s)",
        description="Hold still, have the probe's tip pushed, tilt the tool through a few poses: "
        "per sensor its rate, noise, drift, response to known loads, frame, linearity and "
        "range; one line each and a JSON report; exit 1 (a session refused) when a sensor fails.",
    )
    check.add_argument("config", nargs="?", metavar="CONFIG.yaml", help="the rig's file")
    check.add_argument(
        "--rehearse", action="store_true", help="against the rehearsal world, not a robot"
    )
    check.add_argument(
        "--probe-sensor",
        metavar="fse103|loadcell|none",
        help="the probe sensor (default: the rig file's; fse103 in a rehearsal)",
    )
    check.add_argument(
        "--fault",
        dest="planted",
        action="append",
        default=[],
        metavar="NAME",
        help="plant this fault in the rehearsal (hoh_cosim.rehearsal.planted): ft_sign_flipped, "
        "ft_dead_channel, ft_rate_low, probe_frame_rotated, fse103_nonlinear_housing, "
        "loadcell_saturated (repeatable; default: none, a healthy rig)",
    )
    check.add_argument(
        "--seed", type=int, default=1, metavar="S", help="the rehearsal's seed (default: 1)"
    )
    check.add_argument(
        "--repeat",
        type=int,
        default=0,
        metavar="N",
        help="rehearse N healthy checks (seeds S, S+1, ...) and every planted fault once, and "
        "print the tally (default: 0, one check)",
    )
    check.add_argument(
        "--override",
        action="append",
        default=[],
        metavar="SENSOR",
        help="allow a session although this sensor failed (ft150, fse103, loadcell; repeatable; "
        "default: none)",
    )
    check.add_argument(
        "--out", metavar="FILE", help="the JSON report (default: check-DATE.json in the log dir)"
    )
    check.add_argument(
        "--ur-emulator",
        metavar="HOST",
        help="in a rehearsal, drive the arm through ur-rtde and the emulated UR controller here "
        "(default: the world's arm through shared memory)",
    )


def _hw_check(args: argparse.Namespace) -> int:

    from hoh_cosim.hardware.check import PROBE_SENSORS, SENSORS

    if args.rehearse == (args.config is not None):
        raise ConfigError("hw check: give CONFIG.yaml for a robot, or --rehearse, not both")
    if args.probe_sensor is not None and args.probe_sensor not in PROBE_SENSORS:
        raise ConfigError(
            f"--probe-sensor: expected one of {', '.join(PROBE_SENSORS)}, got {args.probe_sensor!r}"
        )
    for name in args.override:
        if name not in SENSORS:
            raise ConfigError(f"--override: expected one of {', '.join(SENSORS)}, got {name!r}")
    if args.repeat:
        return _check_tally(args)
    if args.rehearse:
        from hoh_cosim.rehearsal.check import rehearse_check

        if args.ur_emulator is not None and not _loopback(args.ur_emulator):
            raise ConfigError(f"--ur-emulator: expected a loopback address, got {args.ur_emulator}")
        out = Path(args.out) if args.out else Path("sessions") / f"check-{_stamp()}.json"
        check_writable(out.parent, f"--out {out}")
        outcome = rehearse_check(
            args.probe_sensor or "fse103",
            tuple(args.planted),
            args.seed,
            ur_host=args.ur_emulator,
            announce=_announce,
        )
        verdicts, about = outcome.verdicts, outcome.about
    else:
        from hoh_cosim.hardware.config import load_config
        from hoh_cosim.hardware.isolation import in_child

        if args.planted:
            raise ConfigError("--fault: a fault is planted only in a rehearsal (--rehearse)")
        config = load_config(args.config)
        out = Path(args.out) if args.out else config.log_dir / f"check-{_stamp()}.json"
        check_writable(out.parent, f"--out {out}")
        return in_child(lambda: _rig_check(config, args, out))
    return _check_verdicts(verdicts, about, args.override, out)


def _check_verdicts(verdicts: Any, about: dict, overrides: list[str], out: Path) -> int:
    """Print a line per sensor, write the report, refuse a session on a failing sensor."""
    from hoh_cosim.calibration import write_json_atomic
    from hoh_cosim.hardware.check import report, session_refusal

    refused = session_refusal(verdicts, overrides)
    for verdict in verdicts:
        overridden = " (overridden)" if not verdict.ok and verdict.sensor in overrides else ""
        print(verdict.line() + overridden, flush=True)
    write_json_atomic(out, report(verdicts, overrides, about))
    print(f"wrote {out}")
    if refused:
        names = ", ".join(refused)
        print(
            f"hoh-cosim: session refused: {names} failed (--override {refused[0]} to run anyway)",
            file=sys.stderr,
            flush=True,
        )
        return 1
    return 0


def _rig_check(config: Any, args: argparse.Namespace, out: Path) -> int:
    """`hw check` on the robot, in the child process of `in_child`."""
    from hoh_cosim.hardware.check_run import check_on_rig

    verdicts, about = check_on_rig(config, args.probe_sensor, announce=_announce)
    return _check_verdicts(verdicts, about, args.override, out)


def _check_tally(args: argparse.Namespace) -> int:
    from hoh_cosim.calibration import write_json_atomic
    from hoh_cosim.rehearsal.check import tally

    if not args.rehearse:
        raise ConfigError("--repeat: a tally runs in rehearsal only (add --rehearse)")
    if args.repeat < 0 or args.planted:
        raise ConfigError(
            f"--repeat: expected N >= 1 healthy runs and no --fault, got {args.repeat}"
        )
    out = Path(args.out) if args.out else None
    if out is not None:
        check_writable(out.parent, f"--out {out}")
    result = tally(
        args.repeat,
        args.seed,
        args.probe_sensor or "fse103",
        tell=lambda line: print(line, flush=True),
    )
    print(result.summary())
    if out is not None:
        write_json_atomic(out, {"summary": result.summary(), "runs": result.reports})
        print(f"wrote {out}")
    return 0 if result.ok else 1


def _default_preset() -> str:
    from hoh_cosim.presets import DEFAULT_PRESET

    return DEFAULT_PRESET


def _stamp() -> str:
    return datetime.datetime.now().strftime("%Y%m%d-%H%M%S")


def _announce(message: str) -> None:
    print(message, flush=True)


def _report(result: Any, log_path: Path) -> int:
    print(f"session ended: {result.cause}")
    print(f"timing: {result.timing.report()}")
    print(f"log: {log_path}")
    return 0 if result.clean else 1


def _hw_run(args: argparse.Namespace) -> int:
    from hoh_cosim.calibration import read_calibration
    from hoh_cosim.hardware.config import load_config
    from hoh_cosim.hardware.ft150 import zero_sensor
    from hoh_cosim.hardware.isolation import in_child

    config = load_config(args.config, args.overrides, args.preset, args.probe_sensor)
    log_path = Path(args.log) if args.log else config.log_dir / f"session-{_stamp()}.mcap"
    _check_log(log_path, "--log" if args.log else f"{config.path}: log_dir")
    if config.calibration is None:
        raise ConfigError(f"{config.path}: calibration: missing (run 'hoh-cosim hw calibrate')")
    calibration = read_calibration(config.calibration)
    view = args if check_view_options(args) else None
    if config.ft150.zero_on_start:
        zero_sensor(config.ft150.host)
    return in_child(lambda: _session(config, calibration, log_path, args.seconds, view))


def _start_view(
    args: argparse.Namespace, controller: Any, phantom_below_m: float | None, title: str
) -> tuple[Any, str | None]:
    """The session's view, started before the session (a port in use: one line, exit 2)."""
    from hoh_cosim.view.session import session_scene, start_session_view

    feed, url = start_session_view(
        session_scene(controller, phantom_below_m),
        web_port=args.view_port if args.view else None,
        record=args.record_view,
        title=title,
    )
    if url is not None:
        print(f"view: {url}", flush=True)
    return feed, url


def _end_view(feed: Any, url: str | None, record: str | None) -> None:
    """The session's view after the session: the recording finished, a live view served until
    Ctrl-C. A view that fails says so; the session's status stands."""
    try:
        feed.finish()
    except RunError as exc:
        print(f"hoh-cosim: the view: {exc}", file=sys.stderr)
    else:
        if record:
            print(f"wrote {record}")
    linger(url, feed.close)


def _check_log(log_path: Path, option: str) -> None:
    """Refuse, before anything runs, a session log that could not be written: a folder where
    nothing can be made, or a file that is there already (a log is never overwritten)."""
    check_writable(log_path.parent, option)
    if os.path.lexists(log_path):
        raise ConfigError(f"{option}: {log_path} exists; a session log is never overwritten")


def _session(
    config: Any,
    calibration: Any,
    log_path: Path,
    seconds: float | None,
    view: argparse.Namespace | None = None,
) -> int:
    """`hw run`'s session, in the child process of `in_child`."""
    from hoh_cosim.hardware.ft150 import FT150Stream
    from hoh_cosim.hardware.probe_port import probe_port
    from hoh_cosim.hardware.robot import RtdeRobot
    from hoh_cosim.hardware.runner import Runner
    from hoh_cosim.hardware.session_log import SessionLog

    robot = RtdeRobot(
        config.robot.host,
        frequency_hz=config.robot.frequency_hz,
        watchdog_hz=config.robot.watchdog_hz,
    )
    ft = FT150Stream(config.ft150.host, config.ft150.port)
    probe = None if config.probe is None else probe_port(config.probe)
    metadata = {
        "kind": "session",
        "config": str(config.path),
        "robot": config.robot.host,
        "R_TS": config.robot.R_TS.tolist(),
        "calibration": str(config.calibration),
    }
    feed, url = (None, None)
    if view is not None:
        feed, url = _start_view(view, config.controller, None, f"session {log_path.stem}")
    try:
        log = SessionLog(log_path, metadata).start()
        runner = Runner(
            config, robot, ft, probe, calibration, log, announce=_announce, observer=feed
        )
        status = _report(runner.run(seconds), log_path)
    except BaseException:
        if feed is not None:
            feed.close()
        raise
    if feed is not None:
        _end_view(feed, url, view.record_view if view is not None else None)
    return status


def _hw_calibrate(args: argparse.Namespace) -> int:
    from hoh_cosim.control.sequencer import SequencerParams
    from hoh_cosim.hardware.config import load_config
    from hoh_cosim.hardware.isolation import in_child

    config = load_config(args.config)
    out = Path(args.out) if args.out else config.calibration
    if out is None:
        raise ConfigError(f"{config.path}: calibration: missing: give --out FILE")
    check_writable(out.parent, f"--out {out}" if args.out else f"{config.path}: calibration")
    params = SequencerParams(tilts=args.tilts, directions=args.directions)
    return in_child(lambda: _calibration(config, params, args.samples, out))


def _calibration(config: Any, params: Any, samples: int, out: Path) -> int:
    """`hw calibrate`'s motion and identification, in the child process of `in_child`."""
    from hoh_cosim.calibration import calibration_to_dict
    from hoh_cosim.hardware.calibrate import calibrate, save
    from hoh_cosim.hardware.ft150 import FT150Stream
    from hoh_cosim.hardware.robot import RtdeRobot

    robot = RtdeRobot(
        config.robot.host,
        frequency_hz=config.robot.frequency_hz,
        watchdog_hz=config.robot.watchdog_hz,
    )
    ft = FT150Stream(config.ft150.host, config.ft150.port)
    run = calibrate(
        robot,
        ft,
        R_TS=config.robot.R_TS,
        params=params,
        samples=samples,
        acceleration=config.robot.acceleration,
        realtime_priority=config.robot.realtime_priority,
        announce=_announce,
    )
    poses = save(run, out)
    residuals = calibration_to_dict(run.calibration)["residuals"]
    cal = run.calibration
    print(
        f"mass {cal.mass_kg:.5f} ± {cal.mass_se_kg:.5f} kg, centre of mass "
        f"{[round(float(x), 5) for x in cal.com_m]} m, from {cal.n_poses} poses"
    )
    print("residual RMS before " + " ".join(f"{v:.4f}" for v in residuals["rms_before"]))
    print("residual RMS after  " + " ".join(f"{v:.4f}" for v in residuals["rms_after"]))
    print(f"wrote {out} and {poses}")
    return 0


def _hw_sensors(args: argparse.Namespace) -> int:
    from hoh_cosim.hardware.diagnostics import describe_streams, read_streams, silent_streams
    from hoh_cosim.hardware.fse103 import FSE103Port
    from hoh_cosim.hardware.ft150 import FT150Stream

    if args.ft is None and args.probe is None:
        raise ConfigError("hw sensors: give --ft HOST[:PORT], --probe DEVICE or both")
    if not args.seconds > 0:
        raise ConfigError(f"--seconds: expected a number > 0, got {args.seconds}")
    ft = FT150Stream(*args.ft) if args.ft else None
    probe = (
        FSE103Port(args.probe, framing=args.framing, byte_order=args.byte_order)
        if args.probe
        else None
    )
    figures = read_streams(ft, probe, args.seconds)
    names = {"ft": ft.describe() if ft else "", "probe": probe.describe() if probe else ""}
    silent = silent_streams(figures, names)
    for line in silent:  # the cause first, then what the streams that answered look like
        print(f"hoh-cosim: {line}", file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps(figures))
    else:
        print(describe_streams(figures, names))
    return 1 if silent else 0


def _rehearsal_params(overrides: list[str], preset: Any) -> tuple[Any, Any]:
    """The estimator's and controller's parameters: the preset's, with `--set` overrides."""
    from hoh_cosim.hardware.config import with_overrides

    params = with_overrides(
        {"estimator": preset.estimator, "controller": preset.controller}, overrides
    )
    return params["estimator"], params["controller"]


def _loadcell_params(settings: list[tuple[str, str]], probe_sensor: str) -> Any:
    """The emulated load cell's parameters with `--loadcell` settings."""
    from hoh_cosim.params import override
    from hoh_cosim.yamlfile import parse_value
    from plant_models.loadcell import LoadCellParams

    params = LoadCellParams()
    if settings and probe_sensor != "loadcell":
        raise ConfigError(f"--loadcell: needs --probe-sensor loadcell, got {probe_sensor}")
    for name, value in settings:
        params = override(params, name, parse_value(f"{name}={value}", value), "--loadcell")
    return params


def _hw_rehearse(args: argparse.Namespace) -> int:
    from hoh_cosim.rehearsal.rehearse import Rehearsal, rehearse

    if not args.seconds > 0:
        raise ConfigError(f"--seconds: expected a number > 0, got {args.seconds}")
    viewing = check_view_options(args)
    log_path = Path(args.log) if args.log else Path("sessions") / f"rehearsal-{_stamp()}.mcap"
    _check_log(log_path, "--log")
    phantom = 0.03 if args.task in CONTACT_TASKS else None
    if args.breathing and phantom is None:
        raise ConfigError(
            f"--breathing: a breathing phantom needs a contact task "
            f"({', '.join(CONTACT_TASKS)}), got --task {args.task}"
        )
    if not 0.0 <= args.breathing <= 30.0:
        raise ConfigError(f"--breathing: expected millimetres from 0 to 30, got {args.breathing:g}")
    from hoh_cosim.presets import DEFAULT_PRESET, load_preset

    if args.away and phantom is None:
        raise ConfigError(
            f"--away: a patient to move away needs a contact task "
            f"({', '.join(CONTACT_TASKS)}), got --task {args.task}"
        )
    away_m, away_s, away_time_s = args.away or (0.0, 0.0, 0.3)
    let_go, retake = args.let_go or (0.0, 0.0)
    preset = load_preset(args.preset or DEFAULT_PRESET)
    estimator, controller = _rehearsal_params(args.overrides, preset)
    probe_sensor = args.probe_sensor or "fse103"
    setup = Rehearsal(
        probe_sensor=probe_sensor,
        loadcell=_loadcell_params(args.loadcell, probe_sensor),
        seconds=args.seconds,
        log_path=log_path,
        task=args.task,
        robot_rate_hz=args.rate,
        faults=tuple(args.faults),
        rebias_samples=args.rebias_samples,
        phantom_below_m=phantom,
        breathing_m=1e-3 * args.breathing,
        let_go_s=let_go,
        retake_s=retake,
        away_m=away_m,
        away_s=away_s,
        away_time_s=away_time_s,
        realtime_priority=args.rt_priority,
        ur_host=args.ur_emulator,
        estimator=estimator,
        controller=controller,
        preset=preset,
    )
    feed, url = (None, None)
    if viewing:
        feed, url = _start_view(args, controller, phantom, f"rehearsal {log_path.stem}")
    try:
        result = rehearse(setup, announce=_announce, observer=feed)
    except BaseException:
        if feed is not None:
            feed.close()
        raise
    if probe_sensor == "fse103":
        print(f"FSE103 framing {result.probe_framing}, byte order {result.probe_byte_order}")
    status = _report(result.session, log_path)
    if feed is not None:
        _end_view(feed, url, args.record_view)
    return status


def _hw_campaign(args: argparse.Namespace) -> int:
    import shutil

    from hoh_cosim.rehearsal import campaign

    for name, value in (("--runs", args.runs), ("--workers", args.workers)):
        if value < 1:
            raise ConfigError(f"{name}: expected a whole number >= 1, got {value}")
    kinds = tuple(campaign.KINDS)
    if args.kinds is not None:
        kinds = tuple(k.strip() for k in args.kinds.split(",") if k.strip())
        unknown = [k for k in kinds if k not in campaign.KINDS]
        if unknown or not kinds:
            raise ConfigError(
                f"--kinds: expected some of {', '.join(campaign.KINDS)}, got {args.kinds!r}"
            )
    out = Path(args.out) if args.out else Path("runs") / f"campaign-{_stamp()}"
    check_out_dir(out, marker="campaign.csv", what="campaign")
    check_writable(out, "--out")
    if (out / "campaign.csv").is_file():  # an earlier campaign: replaced whole
        for old in [*out.glob("run-*"), out / "campaign.csv", out / "summary.json"]:
            if old.is_dir():
                shutil.rmtree(old)
            else:
                old.unlink(missing_ok=True)

    cores = os.cpu_count() or 1
    if args.workers > max(1, cores // 2):
        print(
            f"note: a run takes about a core while it runs; {args.workers} workers on {cores} "
            "cores overload the machine, and runs may stop on their neighbours' load"
        )

    def tell(run: campaign.Run) -> None:
        verdict = "ok" if not run.violations else "VIOLATION: " + "; ".join(run.violations)
        if run.violations and run.rig_stall_s >= campaign.RIG_STALL_S:
            verdict += (
                f" (this machine held the emulated devices back {1e3 * run.rig_stall_s:.0f} ms "
                "during the run)"
            )
        faults = " ".join(f.text() for f in run.faults)
        print(f"run {run.number} (seed {run.seed}) {faults}: {run.cause or 'done'}; {verdict}")

    runs = campaign.run_campaign(
        args.runs, args.seed, args.workers, out, kinds, args.rt_priority, announce=tell
    )
    summary = campaign.summarise(runs, args.seed)
    campaign.write_results(runs, summary, out)
    print(campaign.table(summary))
    for failed in summary["failed_runs"]:
        only = f" --kinds {','.join(kinds)}" if args.kinds is not None else ""
        print(f"re-run alone: hoh-cosim hw campaign --runs 1 --seed {failed['seed']}{only}")
    print(f"wrote {out / 'campaign.csv'} and {out / 'summary.json'}")
    return 1 if summary["violations"] else 0


def _loopback(host: str) -> bool:
    import ipaddress
    import socket

    try:
        addresses = {info[4][0] for info in socket.getaddrinfo(host, None)}
    except socket.gaierror as exc:
        raise ConfigError(f"--host: cannot resolve {host!r}: {exc.strerror}") from None
    return all(ipaddress.ip_address(a.split("%")[0]).is_loopback for a in addresses)


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _hw_emulate(args: argparse.Namespace) -> int:
    import time

    from hoh_cosim.rehearsal.rehearse import UR_SERIES
    from hoh_cosim.rehearsal.ur_controller import UrController
    from hoh_cosim.rehearsal.world import RehearsalWorld, WorldSetup

    if args.seconds is not None and not args.seconds > 0:
        raise ConfigError(f"--seconds: expected a number > 0, got {args.seconds}")
    if not 0 <= args.ft_port <= 65535:
        raise ConfigError(f"--ft-port: expected 0 to 65535, got {args.ft_port}")
    if not _loopback(args.host) and not args.allow_remote:
        raise ConfigError(
            f"--host: {args.host} is not a loopback address; anyone on that network could move "
            "the emulated arm: add --allow-remote to mean it"
        )
    rate = {series: rate for rate, series in UR_SERIES.items()}[args.series]
    # a script that started it may end it with SIGTERM: stop the devices' processes as on Ctrl-C
    signal.signal(signal.SIGTERM, _interrupt)
    setup = WorldSetup(
        robot_rate_hz=rate,
        task=args.task,
        task_start_s=args.task_start,
        phantom_below_m=0.03 if args.task in CONTACT_TASKS else None,
        ft_host=args.host,
        ft_port=args.ft_port,
        probe_sensor=args.probe_sensor or "fse103",
        loadcell=_loadcell_params(args.loadcell, args.probe_sensor or "fse103"),
    )
    with RehearsalWorld(setup) as world:
        try:
            controller = UrController(world, args.host, series=args.series)
            controller.start()
        except (RuntimeError, OSError) as exc:
            raise RunError(f"--host {args.host}: {exc}") from None
        try:
            name = "e-series, 500 Hz" if args.series == "e" else "CB3, 125 Hz"
            print(
                f"UR controller on {args.host} ({name}): dashboard 29999, script 30003, RTDE 30004",
                flush=True,
            )
            print(f"FT-150 stream on {args.host}:{world.ft_port}", flush=True)
            probe = {"fse103": "FSE103", "loadcell": "load cell (Arduino)"}.get(setup.probe_sensor)
            if probe is not None:
                print(f"{probe} on {world.pty_name}", flush=True)
            print("ready" + ("" if args.seconds else " (Ctrl-C ends)"), flush=True)
            deadline = None if args.seconds is None else time.monotonic() + args.seconds
            while deadline is None or time.monotonic() < deadline:
                time.sleep(0.1)
        finally:
            controller.stop()
    print("stopped", flush=True)
    return 0


def _replay(args: argparse.Namespace) -> int:
    from hoh_cosim.hardware.replay import plot_replay, replay

    viewing = check_view_options(args)
    out = Path(args.out) if args.out else Path("runs") / f"replay-{Path(args.log).stem}"
    check_out_dir(out, marker="replay.json", what="replay")
    result = replay(args.log, args.overrides, args.preset)
    view = _replay_view(args, result) if viewing else None
    summary = result.summary()
    png = plot_replay(result)

    def fill(staging: Path) -> None:
        (staging / "replay.png").write_bytes(png)
        (staging / "replay.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")

    replace_dir(out, fill, what="replay")
    if not result.session.complete:
        print(
            f"note: {args.log} ends early (the session was cut off); replayed what is there",
            file=sys.stderr,
        )
    for key, value in summary.items():
        print(f"  {key:<28} {value:.6g}" if isinstance(value, float) else f"  {key:<28} {value}")
    print(f"wrote {out}")
    if view is not None:
        if args.record_view:
            print(f"wrote {args.record_view}")
        linger(view.url, view.close)
    return 0


def _replay_view(args: argparse.Namespace, result: Any) -> Any:
    """The replayed session in the view: shown (and recorded) whole before the results are
    written; a live view is served until Ctrl-C after them."""
    from hoh_cosim.view.session import TIMELINE, log_replay, session_scene
    from hoh_cosim.view.stream import ViewStream

    world = result.session.metadata.get("world") or {}
    stream = ViewStream(
        session_scene(result.controller, world.get("phantom_below_m")),
        title=f"replay {Path(args.log).stem}",
        timeline=TIMELINE,
        web_port=args.view_port if args.view else None,
        record=args.record_view,
        replay=True,
    )
    if stream.url is not None:
        print(f"view: {stream.url}", flush=True)
    try:
        log_replay(result, stream)
        stream.finish()
    except BaseException:
        stream.abandon()
        raise
    return stream


def run_command(args: argparse.Namespace) -> int | None:
    """Run a hardware command if `args` names one; None otherwise."""
    if args.command == "replay":
        return _replay(args)
    if args.command != "hw":
        return None
    handlers = {
        "run": _hw_run,
        "calibrate": _hw_calibrate,
        "sensors": _hw_sensors,
        "rehearse": _hw_rehearse,
        "emulate": _hw_emulate,
        "campaign": _hw_campaign,
        "check": _hw_check,
    }
    if args.hw_command not in handlers:
        raise ConfigError("hw: expected a command: " + ", ".join(handlers))
    try:
        return handlers[args.hw_command](args)
    except OSError as exc:
        raise io_failure(exc) from None
