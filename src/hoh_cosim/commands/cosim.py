"""The co-simulation commands of `hoh-cosim`:

hoh-cosim [run] SCENARIO.yaml [--out DIR] [--engine fmu|inprocess|libcosim|ecos] [--duration S]
                              [--coupling gauss-seidel|jacobi|jacobi-eager] [--seed N]
                              [--preset NAME|FILE] [--set component.parameter=value ...]
                              [--view] [--record-view FILE.rrd] [--view-port PORT]
hoh-cosim build-fmus [--out DIR]
hoh-cosim export SCENARIO.yaml --out DIR [--check] [--duration S] [--seed N] [--preset NAME|FILE] [--set ...]
hoh-cosim presets [NAME|FILE] [--json]
hoh-cosim identify-gravity POSES.csv [--out calibration.json] [--gravity GX,GY,GZ]
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from hoh_cosim.commands import (
    ArgumentParser,
    add_set_option,
    add_view_options,
    check_view_options,
    linger,
)
from hoh_cosim.cosim import COUPLINGS, ENGINE_COUPLING, ENGINES, EXTERNAL_ENGINES
from hoh_cosim.errors import ConfigError
from hoh_cosim.results import FORMATS

__all__ = ["COMMANDS", "add_commands", "run_command", "run_scenario_command"]

COMMANDS = ("run", "build-fmus", "export", "identify-gravity", "presets")


def _gravity(text: str) -> list[float]:
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(
            f"expected three comma-separated numbers like 0,0,-9.81, got {text!r}"
        )
    return values


def add_preset_option(parser: argparse.ArgumentParser, default: str) -> None:
    """--preset NAME|FILE: the estimator's and the controller's parameters (hoh_cosim.presets)."""
    from hoh_cosim.presets import preset_names

    parser.add_argument(
        "--preset",
        metavar="NAME|FILE",
        help=f"the estimator's and the controller's preset: {', '.join(preset_names())}, or a "
        f"preset file; --set changes it further (default: {default}; 'hoh-cosim presets' "
        "lists them)",
    )


def add_scenario_options(parser: argparse.ArgumentParser) -> None:
    """--preset, --duration, --seed and --set: what changes a scenario as it is loaded."""
    from hoh_cosim.presets import DEFAULT_PRESET

    add_preset_option(parser, f"the scenario's preset, else {DEFAULT_PRESET}")
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="simulated seconds (default: the scenario's duration_s)",
    )
    parser.add_argument(
        "--seed", type=int, metavar="N", help="the random seed (default: the scenario's seed)"
    )
    add_set_option(
        parser,
        "set a component's parameter, e.g. controller.contact_compensation=false or "
        "estimator.filter=butterworth (repeatable; default: the scenario's values)",
    )


def add_fmi_option(parser: argparse.ArgumentParser, help: str) -> None:
    """`--fmi 2|3`: FMI 2.0 (pythonfmu, the default) or FMI 3.0 (pythonfmu3) FMUs."""
    parser.add_argument(
        "--fmi", type=int, choices=(2, 3), default=2, help=f"{help}: 2.0 (default) or 3.0"
    )


def check_seed(args: argparse.Namespace) -> None:
    if args.seed is not None and args.seed < 0:
        raise ConfigError(f"--seed: expected an integer >= 0, got {args.seed}")


def add_commands(sub: argparse._SubParsersAction) -> None:
    """`run`, `build-fmus`, `export`, `presets` and `identify-gravity` on the main parser's
    subparsers."""
    run = sub.add_parser(
        "run",
        help="run a co-simulation scenario and write its results",
        description=_RUN_DESCRIPTION,
    )
    _add_run_arguments(run)

    build = sub.add_parser(
        "build-fmus",
        help="build every component's FMU",
        description=(
            "Build every component's FMI 2.0 co-simulation FMU with pythonfmu (--fmi 3: FMI 3.0 "
            "with pythonfmu3). Without --out, into "
            "the cache a scenario run uses (only what is missing or out of date); with --out, all of "
            "them afresh into DIR."
        ),
    )
    build.add_argument(
        "--out",
        metavar="DIR",
        help="where to put the .fmu files (default: the cache a scenario run uses)",
    )
    add_fmi_option(build, "the FMI version")

    export = sub.add_parser(
        "export",
        help="write a scenario's FMUs, an SSP archive and a README for another tool",
        description=(
            "Write the scenario's FMUs (validated), an SSP 1.0 archive of the system with its "
            "connections and parameter values, the same system as OspSystemStructure.xml, and a "
            "README with every variable and what a host needs."
        ),
    )
    export.add_argument("scenario", metavar="SCENARIO.yaml", help="the scenario to export")
    export.add_argument("--out", required=True, metavar="DIR", help="the export directory")
    export.add_argument(
        "--check",
        action="store_true",
        help=(
            "then run each FMU alone in a clean virtual environment that has only the FMUs' "
            "declared requirements and fmpy, and compare it with the same run here (one line "
            "each; exit 1 if one fails)"
        ),
    )
    add_fmi_option(export, "the FMI version of the exported FMUs")
    export.add_argument(
        "--check-engines",
        action="store_true",
        help=(
            "--check, and then the exported SSP archive in libcosim and in ecos in such an "
            "environment (with the engines added), over the scenario's duration, compared with "
            "our master run with each engine's coupling"
        ),
    )
    add_scenario_options(export)

    presets = sub.add_parser(
        "presets",
        help="list the presets, with their measured figures",
        description=(
            "List the presets (a named set of the estimator's and the controller's parameters and "
            "the session steps they need, chosen with --preset NAME), one line each with its "
            "measured figures; with NAME or FILE, every value it sets."
        ),
    )
    presets.add_argument(
        "preset", nargs="?", metavar="NAME|FILE", help="show this preset's values in full"
    )
    presets.add_argument("--json", action="store_true", help="one JSON object on stdout")

    ident = sub.add_parser(
        "identify-gravity",
        help="identify the tool's mass, centre of mass and sensor offsets from static poses",
        description=(
            "Identify mass, centre of mass, force and torque bias of the tool on the wrist F/T "
            "sensor from static, untouched poses (header rx,ry,rz,fx,fy,fz,tx,ty,tz: rotation "
            "vector of R_BS in rad, raw averaged reading in N and N·m)."
        ),
    )
    ident.add_argument(
        "poses", metavar="POSES.csv", help="one static pose a row: rx,ry,rz,fx,fy,fz,tx,ty,tz"
    )
    ident.add_argument(
        "--out",
        default="calibration.json",
        metavar="FILE",
        help="where to write the calibration (default: calibration.json)",
    )
    ident.add_argument(
        "--gravity",
        type=_gravity,
        default=None,
        metavar="GX,GY,GZ",
        help="gravity in the base frame, m/s² (default: 0,0,-9.81)",
    )


_RUN_DESCRIPTION = (
    "Run a co-simulation scenario and write signals.parquet (or signals.csv), summary.json and "
    "plots into the output directory. 'hoh-cosim SCENARIO.yaml' is short for 'hoh-cosim run "
    "SCENARIO.yaml'."
)


def _scenario_parser(others: Sequence[str]) -> argparse.ArgumentParser:
    """The bare `hoh-cosim SCENARIO.yaml`'s parser: the `run` command's arguments."""
    parser = ArgumentParser(
        prog="hoh-cosim",
        usage="hoh-cosim SCENARIO.yaml [options]",
        description=_RUN_DESCRIPTION,
        epilog="Other commands: " + ", ".join(others) + " (see hoh-cosim COMMAND --help).",
    )
    _add_run_arguments(parser)
    return parser


def _add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """The scenario run's arguments, the same on `hoh-cosim run` and `hoh-cosim SCENARIO.yaml`."""
    parser.add_argument(
        "scenario", metavar="SCENARIO.yaml", help="the scenario (see scenarios/ and its README)"
    )
    parser.add_argument(
        "--out",
        metavar="DIR",
        help="results directory, replaced whole if it holds an earlier run "
        "(default: runs/<scenario name>)",
    )
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default="fmu",
        help=(
            "step the components as FMUs through fmpy (default), as Python blocks in-process, or "
            "as FMUs in libcosim or ecos"
        ),
    )
    parser.add_argument(
        "--coupling",
        choices=COUPLINGS,
        default="gauss-seidel",
        help=(
            "how our master passes outputs on: in the file's order (default), or as libcosim "
            "(jacobi) or ecos (jacobi-eager) do"
        ),
    )
    add_fmi_option(parser, "the FMI version of the FMUs the fmu engine builds and steps")
    parser.add_argument(
        "--format",
        choices=FORMATS,
        default="parquet",
        help=(
            "the signals' file: signals.parquet, compact and typed (default; pandas, polars, "
            "MATLAB and pyarrow read it), or signals.csv, text"
        ),
    )
    add_scenario_options(parser)
    parser.add_argument(
        "--quiet", action="store_true", help="no progress bar and no metric table (default: both)"
    )
    add_view_options(parser, "the run")


def _metric_text(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list):
        return "[" + ", ".join(_metric_text(v) for v in value) + "]"
    return "n/a" if value is None else str(value)


def run_scenario_command(argv: Sequence[str], others: Sequence[str]) -> int:
    """The bare `hoh-cosim SCENARIO.yaml [options]`; `others`: the commands, for its help."""
    return _run(_scenario_parser(others).parse_args(argv))


def _run(args: argparse.Namespace) -> int:
    from hoh_cosim.cosim.run import run_scenario

    views: list[Any] = []
    watch = None
    if check_view_options(args):

        def watch(scenario: Any) -> Any:
            from hoh_cosim.view.cosim import CosimView

            view = CosimView(
                scenario,
                web_port=args.view_port if args.view else None,
                record=args.record_view,
            )
            views.append(view)
            if view.url is not None:
                print(f"view: {view.url}", flush=True)
            return view

    if args.engine in EXTERNAL_ENGINES and args.coupling != "gauss-seidel":
        raise ConfigError(
            f"--coupling {args.coupling}: --engine {args.engine} has its own coupling "
            f"({ENGINE_COUPLING[args.engine]})"
        )
    if args.fmi == 3 and args.engine != "fmu":
        raise ConfigError(f"--fmi 3: only --engine fmu steps FMUs of FMI 3.0, not {args.engine}")
    check_seed(args)
    result = run_scenario(
        args.scenario,
        out=args.out,
        engine=args.engine,
        coupling=args.coupling,
        duration_s=args.duration,
        seed=args.seed,
        overrides=args.overrides,
        progress=not args.quiet,
        fmt=args.format,
        preset=args.preset,
        fmi=args.fmi,
        watch=watch,
    )
    for note in result.report.notes:
        print(f"hoh-cosim: note: {note}", file=sys.stderr)
    if not args.quiet:
        s = result.summary
        m = s["metrics"]
        print(
            f"{s['scenario']}: {s['duration_s']:g} s simulated in {m['wall_s']:.2f} s "
            f"({_metric_text(m['realtime_factor'])}x real time, engine {s['engine']}, seed {s['seed']}"
            + (f", preset {s['preset']})" if s["preset"] else ")")
        )
        width = max(len(k) for k in s["metrics"])
        for key, value in s["metrics"].items():
            if key not in ("wall_s", "realtime_factor"):
                print(f"  {key:<{width}}  {_metric_text(value)}")
    print(f"wrote {result.out}")
    if args.record_view:
        print(f"wrote {args.record_view}")
    if views:
        linger(views[0].url, views[0].close)
    return 0


def _build_fmus(args: argparse.Namespace) -> int:
    from hoh_cosim.fmi.build import default_cache_dir, ensure_fmus
    from hoh_cosim.kinds import KINDS
    from hoh_cosim.results import check_writable

    out = Path(args.out) if args.out else default_cache_dir()
    if args.out:
        check_writable(out, f"--out {args.out}")
    paths = ensure_fmus(KINDS, out, force=args.out is not None, fmi=args.fmi)
    for kind, path in paths.items():
        print(f"{kind:<11} {path}")
    return 0


def _export(args: argparse.Namespace) -> int:
    from hoh_cosim.cosim.export import export_scenario

    check_seed(args)
    result = export_scenario(
        args.scenario,
        args.out,
        overrides=args.overrides,
        duration_s=args.duration,
        seed=args.seed,
        command=shlex.join(["hoh-cosim", "export", *args.argv]),
        preset=args.preset,
        fmi=args.fmi,
    )
    for component, path in result.fmus.items():
        print(f"{component:<11} {path}")
    print(f"wrote {result.ssp} and {result.out / 'README.md'}")
    if not (args.check or args.check_engines):
        return 0
    from hoh_cosim.fmi.build import default_cache_dir
    from hoh_cosim.fmi.hostcheck import HEADER, check_export

    fmus = sorted(set(result.fmus.values()))
    print(f"checking {len(fmus)} FMUs in a clean environment (made once, then reused) ...")
    rows = check_export(fmus, default_cache_dir())
    print(HEADER)
    for row in rows:
        print(row.line())
    failed = sum(not row.ok for row in rows)
    print(f"{len(rows) - failed} of {len(rows)} FMUs ran alone in a host without hoh-cosim")
    if args.check_engines:
        from hoh_cosim.cosim.portable import check_engines

        print("the SSP archive in libcosim and ecos in a clean environment ...")
        engine_rows = check_engines(result.scenario, result.out, default_cache_dir())
        print(HEADER)
        for row in engine_rows:
            print(row.line())
        bad = sum(not row.ok for row in engine_rows)
        ran = [row for row in engine_rows if not row.skipped]
        print(
            f"{len(ran) - bad} of {len(ran)} (engine, FMU) pairs agree with our master"
            + (f"; {len(engine_rows) - len(ran)} skipped" if len(ran) < len(engine_rows) else "")
        )
        failed += bad
    return 1 if failed else 0


def _fmt(values: Sequence[float], digits: int = 5, signed: bool = True) -> str:
    sign = "+" if signed else ""
    return "[" + ", ".join(f"{v:{sign}.{digits}f}" for v in values) + "]"


def _identify_gravity(args: argparse.Namespace) -> int:
    import numpy as np

    from hoh_cosim.calibration import read_poses_csv, write_calibration
    from hoh_cosim.control.gravity import identify_gravity
    from hoh_cosim.control.vectors import GRAVITY_B
    from hoh_cosim.errors import IdentificationError, InputFileError
    from hoh_cosim.results import check_writable

    if Path(args.out).parent.exists():  # else the write says the folder does not exist
        check_writable(Path(args.out).parent, f"--out {args.out}")
    g_B = GRAVITY_B if args.gravity is None else np.array(args.gravity)
    R_BS, wrench = read_poses_csv(args.poses)
    try:
        cal = identify_gravity(R_BS, wrench, g_B)
    except IdentificationError as exc:
        raise InputFileError(args.poses, "", str(exc)) from None
    g = float(np.linalg.norm(g_B))
    print(
        f"identified from {cal.n_poses} poses in {args.poses} "
        f"(gravity {_fmt(g_B, 3)} m/s², condition number {cal.condition_number:.3g})"
    )
    print(
        f"  mass            {cal.mass_kg:.5f} ± {cal.mass_se_kg:.5f} kg   "
        f"(mg = {cal.mass_kg * g:.4f} N)"
    )
    print(f"  centre of mass  {_fmt(cal.com_m)} ± {_fmt(cal.com_se_m, signed=False)} m")
    print(
        f"  force bias      {_fmt(cal.force_bias_N, 4)} ± {_fmt(cal.force_bias_se_N, 4, False)} N"
    )
    print(
        f"  torque bias     {_fmt(cal.torque_bias_Nm, 5)} ± {_fmt(cal.torque_bias_se_Nm, 5, False)} N·m"
    )
    print("  residuals          fx       fy       fz       tx       ty       tz   (N, N·m)")
    for label, values in (
        ("RMS before", cal.residual_rms_before),
        ("max before", cal.residual_max_before),
        ("RMS after ", cal.residual_rms_after),
        ("max after ", cal.residual_max_after),
    ):
        print(f"  {label}  " + " ".join(f"{v:8.4f}" for v in values))
    print("  (before: reading minus the identified bias; after: minus the tool-weight model too)")
    write_calibration(args.out, cal)
    print(f"wrote {args.out}")
    return 0


def _presets(args: argparse.Namespace) -> int:
    from hoh_cosim.presets import figure_lines, load_figures, load_preset, preset_names

    figures = load_figures()
    if args.preset is not None:
        preset = load_preset(args.preset)
        if args.json:
            print(json.dumps(_preset_json(preset, figures), indent=1))
            return 0
        print(f"{preset.label}: {preset.description}")
        if preset.probe_check_s:
            print(f"  session: a probe check of {preset.probe_check_s:g} s at the start")
        for name, value in preset.changes().items():
            print(f"  {name} = {value}")
        for line in figure_lines(figures.get(preset.name)):
            print(f"  measured: {line}")
        return 0
    chosen = [load_preset(name) for name in preset_names()]
    if args.json:
        print(json.dumps({p.name: _preset_json(p, figures) for p in chosen}, indent=1))
        return 0
    width = max(len(p.name) for p in chosen)
    indent = " " * (width + 2)
    for preset in chosen:
        text = textwrap.fill(
            preset.description,
            100,
            initial_indent=f"{preset.name:<{width}}  ",
            subsequent_indent=indent,
        )
        print(text)
        for line in figure_lines(figures.get(preset.name)) or ["not measured yet"]:
            print(textwrap.fill(line, 100, initial_indent=indent, subsequent_indent=indent + "  "))
    source = figures.get("_measured_by")
    if source:
        print(f"measured by: {source}")
    return 0


def _preset_json(preset: Any, figures: dict[str, Any]) -> dict[str, Any]:
    return {
        "name": preset.name,
        "description": preset.description,
        "file": str(preset.path),
        "probe_check_s": preset.probe_check_s,
        "changes": preset.changes(),
        "figures": figures.get(preset.name),
    }


def run_command(args: argparse.Namespace) -> int | None:
    """Run a co-simulation command if `args` names one; None otherwise."""
    if args.command == "run":
        return _run(args)
    if args.command == "presets":
        return _presets(args)
    if args.command == "identify-gravity":
        return _identify_gravity(args)
    if args.command == "build-fmus":
        return _build_fmus(args)
    if args.command == "export":
        return _export(args)
    return None
