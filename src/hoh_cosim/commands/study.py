"""The study commands of `hoh-cosim`:

    hoh-cosim sweep SWEEP.yaml [--scheduler ADDRESS] [--workers N] [--out DIR] [--engine E]
    hoh-cosim report [--out DIR] [--quick] [--workers N] [--scheduler ADDRESS] [--scenarios DIR]
    hoh-cosim tune [--out DIR] [-n N] [--seed S] [--seeds 1,2,3] [--workers N] [--scheduler ADDRESS]
    hoh-cosim probe-correction [--out DIR] [--seed S] [--engine E] [--workers N] [--quick]
    hoh-cosim study clinical [--quick] [--operators N] [--seed S] [--preset NAME ...] [--figures F]
                             [--workers W] [--scheduler ADDR]
                             [--out DIR] [--set C.P=V ...] [--record-view]

`--workers 0` runs everything serially in this process (no Dask).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from hoh_cosim.commands import EXIT_FAILED, EXIT_OK, add_set_option
from hoh_cosim.errors import ConfigError

__all__ = ["COMMANDS", "add_commands", "run_command"]

COMMANDS = ("sweep", "report", "tune", "probe-correction", "study")
STUDIES = ("clinical",)


def _cluster_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="local worker processes (default: one per core; 0: run serially, without Dask)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _seeds(text: str) -> tuple[int, ...]:
    try:
        seeds = tuple(int(p) for p in text.split(","))
    except ValueError:
        seeds = ()
    if not seeds or min(seeds) < 0:
        raise argparse.ArgumentTypeError(f"expected integers >= 0 like 1,2,3, got {text!r}")
    return seeds


def add_commands(sub) -> None:
    sweep = sub.add_parser(
        "sweep",
        help="run many variants of a scenario on Dask, one table row per run",
        description=(
            "Run a grid or a seeded random sample of scenario variants (any --set parameter, any "
            "seed) on a local Dask cluster or an existing one; write runs.csv and runs.parquet "
            "with the varied parameters, every metric, status and wall time."
        ),
    )
    sweep.add_argument(
        "sweep",
        metavar="SWEEP.yaml",
        help="the sweep (see studies/slopes.yaml, hoh_cosim.study.sweep)",
    )
    sweep.add_argument(
        "--out", metavar="DIR", help="the results directory (default: sweeps/<sweep name>)"
    )
    sweep.add_argument(
        "--engine",
        choices=("inprocess", "fmu"),
        help="the engine of every run (default: the sweep file's)",
    )
    _cluster_options(sweep)

    report = sub.add_parser(
        "report",
        help="the verification report: the seed's experiments, linear analysis, tuning",
        description=(
            "Run the seed's experiments, the filter and admittance comparisons, the linear "
            "analysis and the tuning search, and write index.html, report.md, figures, runs.csv "
            "and summary.json."
        ),
    )
    report.add_argument(
        "--out", metavar="DIR", default="report", help="the report's directory (default: report)"
    )
    report.add_argument(
        "--quick",
        action="store_true",
        help="fewer, shorter runs: under a minute on 2 cores (default: the full report)",
    )
    report.add_argument(
        "--scenarios",
        metavar="DIR",
        default="scenarios",
        help="where circles.yaml and the other scenarios are (default: ./scenarios)",
    )
    _cluster_options(report)

    tune = sub.add_parser(
        "tune",
        help="search the Kalman filter and eq. 10 gains for least effort and path error",
        description=(
            "Search the Kalman q multiples, the deadband and the slope on circles, subject to "
            "beating the seed on noise and lag, the loop's stability margins, and a still tip at "
            "rest; write candidates.csv and best.json."
        ),
    )
    tune.add_argument(
        "--out", metavar="DIR", default="tune", help="the tuning's directory (default: tune)"
    )
    tune.add_argument("-n", type=int, default=40, metavar="N", help="candidates (default 40)")
    tune.add_argument("--seed", type=int, default=1, help="of the candidate sample (default 1)")
    tune.add_argument("--seeds", type=_seeds, default=(1, 2), help="scenario seeds (default 1,2)")
    tune.add_argument(
        "--scenarios",
        metavar="DIR",
        default="scenarios",
        help="where circles.yaml and the other scenarios are (default: ./scenarios)",
    )
    _cluster_options(tune)

    probe = sub.add_parser(
        "probe-correction",
        help="the seed's probe-force network against the online map, day one and day two",
        description=(
            "Record pushes on the probe tip on two simulated days, train the seed's networks on "
            "day one, compare raw, network and online map against the wrist sensor on both days, "
            "and run contact_scan_online with each correction in the loop; write report.md, "
            "table.csv, summary.json, network.json and the figures."
        ),
    )
    probe.add_argument(
        "--out",
        metavar="DIR",
        default="probe_correction",
        help="the results directory (default: probe_correction)",
    )
    probe.add_argument("--seed", type=int, default=1, help="of the recordings (default 1)")
    probe.add_argument(
        "--engine",
        choices=("inprocess", "fmu"),
        default="inprocess",
        help="how the runs step their components (default: inprocess)",
    )
    probe.add_argument("--quick", action="store_true", help="shorter recordings and runs")
    probe.add_argument(
        "--scenarios",
        metavar="DIR",
        default="scenarios",
        help="where circles.yaml and the other scenarios are (default: ./scenarios)",
    )
    _cluster_options(probe)

    study = sub.add_parser(
        "study",
        help="studies over a population: clinical (freehand against assisted scanning)",
        description="Studies over a population of simulated sonographers.",
    )
    study_sub = study.add_subparsers(
        dest="study", metavar="STUDY", parser_class=type(study), required=True
    )
    clinical = study_sub.add_parser(
        "clinical",
        help="freehand against assisted scanning on a breathing patient, N operators",
        description=(
            "N simulated sonographers (hand, tremor, strength, grip; a breathing patient each) "
            "reach a view and hold it, scan a 10 cm line at 8 N, press to 15 N and hold a view "
            "while the patient moves away, freehand and assisted under each preset; paired "
            "comparisons per operator with 95 % confidence intervals, the targets; write "
            "index.html, report.md, runs.csv, operators.csv and summary.json."
        ),
    )
    clinical.add_argument(
        "--quick",
        action="store_true",
        help="3 operators (unless --operators) and shorter holds: under 3 minutes on 2 cores",
    )
    clinical.add_argument(
        "--operators", type=int, metavar="N", help="simulated sonographers (default 20; 3 quick)"
    )
    clinical.add_argument(
        "--seed", type=int, default=1, help="of the population and its patients (default 1)"
    )
    clinical.add_argument(
        "--out", metavar="DIR", default="clinical", help="the study's directory (default: clinical)"
    )
    clinical.add_argument(
        "--scenarios",
        metavar="DIR",
        default="scenarios",
        help="where clinical_freehand.yaml and clinical_assisted.yaml are (default: ./scenarios)",
    )
    clinical.add_argument(
        "--preset",
        dest="presets",
        action="append",
        default=[],
        metavar="NAME|FILE",
        help="an assisted mode: this preset (repeatable; default: seed, transparent, checked, "
        "hold, follow, glide and clinical)",
    )
    add_set_option(
        clinical,
        "set a parameter in every assisted mode's runs, after the mode's preset, e.g. "
        "controller.translation.slope=[0.04,0.04,0.04] (repeatable; freehand as it is; default: "
        "none)",
    )
    clinical.add_argument(
        "--record-view",
        action="store_true",
        help="also keep one Rerun recording of the 3D view per kept run (the first three "
        "operators' runs) in DIR/views/, to open with 'python -m hoh_cosim.view serve FILE.rrd'; "
        "needs the view extra (default: none)",
    )
    clinical.add_argument(
        "--figures",
        metavar="FILE",
        help="also write the presets' headline figures to FILE, as 'hoh-cosim presets' shows them "
        "(src/hoh_cosim/presets/figures.json in a checkout; default: none)",
    )
    _cluster_options(clinical)


def _check_workers(args: argparse.Namespace) -> None:
    if args.workers is not None and args.workers < 0:
        raise ConfigError(f"--workers: expected an integer >= 0, got {args.workers}")


def _sweep(args: argparse.Namespace) -> int:
    from hoh_cosim.cosim.run import jsonable
    from hoh_cosim.results import check_out_dir, replace_dir
    from hoh_cosim.study.sweep import load_sweep, run_variants, table_rows, write_table

    _check_workers(args)
    sweep = load_sweep(args.sweep, engine=args.engine)
    out = Path(args.out) if args.out else Path("sweeps") / sweep.name
    check_out_dir(out, marker="runs.csv", what="sweep")
    start = time.perf_counter()
    outcomes = run_variants(
        sweep.variants,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.quiet,
        label=sweep.name,
    )
    columns, rows = table_rows(outcomes)
    failed = [o for o in outcomes if not o.ok]
    info = {
        "sweep": sweep.name,
        "file": str(sweep.path),
        "scenario": str(sweep.scenario),
        "engine": sweep.engine,
        "runs": len(outcomes),
        "failed": len(failed),
        "wall_s": time.perf_counter() - start,
        "scheduler": args.scheduler or "local",
    }
    written: list[Path] = []

    def fill(staging: Path) -> None:
        written.extend(out / p.name for p in write_table(staging, columns, rows))
        (staging / "sweep.json").write_text(
            json.dumps(jsonable(info), indent=2, allow_nan=False) + "\n", encoding="utf-8"
        )

    replace_dir(out, fill, what="sweep")
    print(
        f"{sweep.name}: {len(outcomes)} runs, {len(failed)} failed, {info['wall_s']:.1f} s "
        f"({info['scheduler']})"
    )
    for o in failed[:5]:
        print(f"hoh-cosim: run {o.variant.index} failed: {o.error}", file=sys.stderr)
    for path in written:
        print(f"wrote {path}")
    return EXIT_OK if len(failed) < len(outcomes) or not outcomes else EXIT_FAILED


def _report(args: argparse.Namespace) -> int:
    from hoh_cosim.study.verification import FULL, QUICK, build_report

    _check_workers(args)
    result = build_report(
        args.out,
        QUICK if args.quick else FULL,
        scenarios=args.scenarios,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.quiet,
    )
    s = result.summary
    d = s["default"]
    print(f"report: {s['runs']} runs in {s['wall_s']:.0f} s, {len(s['failed_runs'])} failed")
    print(
        f"  defaults: attenuation {d['attenuation_min']:.2f}x at {d['filter_lag_ms']:.1f} ms "
        f"lag, gain margin {d['gain_margin']:.2f}, critical slope {d['critical_slope']:.4f}"
    )
    t = s["tuned"]
    if t is None:
        print("  tuned: no feasible candidate")
    else:
        print(
            f"  tuned: attenuation {t['attenuation_min']:.2f}x at {t['filter_lag_ms']:.1f} ms lag, "
            f"score {t['score']:.3f} (defaults 2): " + " ".join(f"--set {o}" for o in t["set"])
        )
    for line in s["failed_runs"][:5]:
        print(f"hoh-cosim: failed: {line}", file=sys.stderr)
    print(f"wrote {result.out / 'index.html'}")
    return EXIT_FAILED if s["failed_runs"] else EXIT_OK


def _tune(args: argparse.Namespace) -> int:
    from hoh_cosim.study.tune import run_tune

    _check_workers(args)
    if args.n < 0:
        raise ConfigError(f"-n: expected an integer >= 0, got {args.n}")
    result = run_tune(
        args.out,
        args.scenarios,
        n=args.n,
        seed=args.seed,
        seeds=args.seeds,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.quiet,
    )
    top = result["best"]
    ref = result["defaults"]
    print(
        f"tune: {result['candidates']} candidates, {result['ran']} ran, "
        f"{result['feasible']} feasible"
    )
    print(
        f"  defaults: attenuation {ref['attenuation_min']:.2f}x at {ref['filter_lag_ms']:.1f} ms, "
        f"effort {ref['hand_force_rms_N']:.2f} N, path error {1e3 * ref['path_rms_error_m']:.1f} mm, "
        f"gain margin {ref['gain_margin']:.2f}"
    )
    if top is None:
        print("  no feasible candidate")
    else:
        print(
            f"  best: attenuation {top['attenuation_min']:.2f}x at {top['filter_lag_ms']:.1f} ms, "
            f"effort {top['hand_force_rms_N']:.2f} N, path error "
            f"{1e3 * top['path_rms_error_m']:.1f} mm, gain margin {top['gain_margin']:.2f}, "
            f"score {top['score']:.3f}"
        )
        print("  " + " ".join(f"--set {o}" for o in top["set"]))
    print(f"wrote {Path(args.out) / 'candidates.csv'}")
    return EXIT_OK


def _probe_correction(args: argparse.Namespace) -> int:
    from hoh_cosim.study.probe import QUICK, ProbeSettings, run_probe_correction

    _check_workers(args)
    if args.seed < 0:
        raise ConfigError(f"--seed: expected an integer >= 0, got {args.seed}")
    study = run_probe_correction(
        args.out,
        args.scenarios,
        seed=args.seed,
        engine=args.engine,
        settings=QUICK if args.quick else ProbeSettings(),
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.quiet,
    )
    s = study.summary
    net = s["network"]

    def axes(values: list) -> str:
        return "/".join("n/a" if v is None else f"{v:.3f}" for v in values)

    print(f"probe-correction: {s['training_samples']} training samples, {s['wall_s']:.0f} s")
    print(
        f"  network validation r {axes(net['validation_correlation'])} "
        f"(seed {axes(net['seed_validation_correlation'])})"
    )
    print(f"  {'':8} {'':8} {'correlation x/y/z':>20} {'RMS error x/y/z [N]':>20}")
    for row in study.table:
        print(
            f"  {row['day']:8} {row['correction']:8} {axes(row['correlation']):>20} "
            f"{axes(row['rms_N']):>20}"
        )
    for row in study.contact:
        if row["status"] != "ok":
            print(f"  contact_scan {row['day']}, {row['correction']}: failed: {row['error']}")
            continue
        bounce = row["max_bounce_m"]
        print(
            f"  contact_scan {row['day']}, {row['correction']}: {row['contact_losses']} losses, "
            f"force {_num(row['contact_force_mean_N'])} +- {_num(row['contact_force_std_N'])} N, "
            f"bounce {_num(None if bounce is None else 1e3 * bounce)} mm, "
            f"drift flagged {_num(row['drift_flagged_fraction'])}, {row['controller_flags']}"
        )
    print(f"wrote {study.out / 'report.md'}")
    failed = [r for r in study.contact if r["status"] != "ok"]
    return EXIT_FAILED if failed else EXIT_OK


def _num(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3g}"


def _pct(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.1f}"


def _mm(value: float | None) -> float | None:
    return None if value is None else 1e3 * value


def _clinical(args: argparse.Namespace) -> int:
    from hoh_cosim.study.clinical import TASKS, run_clinical

    result = run_clinical(
        args.out,
        quick=args.quick,
        operators=args.operators,
        seed=args.seed,
        workers=args.workers,
        scheduler=args.scheduler,
        scenarios=args.scenarios,
        progress=not args.quiet,
        overrides=args.overrides,
        presets=args.presets or None,
        figures_out=args.figures,
        record_views=args.record_view,
    )
    s = result.summary
    print(
        f"clinical: {s['operators']} operators, {s['runs']} runs in {s['wall_s']:.0f} s, "
        f"{len(s['failed_runs'])} failed"
    )
    if s["overrides"]:
        print("  every assisted mode with " + " ".join(f"--set {t}" for t in s["overrides"]))
    assisted = [m for m in s["modes"] if m in s["presets"]]
    width = max(len(s["modes"][mode]) for mode in assisted)
    print(f"  {'task':7} {'mode':{width}}  {'hand force less [%]':>26}  {'jitter less [%]':>26}")
    for task in TASKS:
        for mode in assisted:
            e = s["tasks"][task][mode]
            force, jitter = e["hand_force_reduction_pct"], e["jitter_improvement_pct"]
            print(
                f"  {task:7} {s['modes'][mode]:{width}}  "
                f"{_pct(force['mean']):>7} (smallest {_pct(force['min']):>7})  "
                f"{_pct(jitter['mean']):>7} (smallest {_pct(jitter['min']):>7})"
            )
    print("  targets (met / not met / not judged):")
    for mode in assisted:
        t = s["targets"][mode]
        flags = {
            "effort": t["hand_force_reduction_met"],
            "jitter": t["jitter_improvement_met"],
            "hold": t.get("hold_met", "n/a"),
            "recovery": t["recovery_met"],
            "release": t["release_met"],
        }
        print(
            f"  {s['modes'][mode]:{width}}  "
            + ", ".join(f"{k} {_judged(v)}" for k, v in flags.items())
        )
    for line in s["failed_runs"][:5]:
        print(f"hoh-cosim: failed: {line}", file=sys.stderr)
    print(f"wrote {result.out / 'index.html'}")
    if args.figures:
        print(f"wrote {args.figures}")
    return EXIT_FAILED if s["failed_runs"] else EXIT_OK


def _judged(flag: object) -> str:
    return {True: "met", False: "not met", None: "not judged"}.get(flag, str(flag))  # type: ignore[call-overload]


def run_command(args: argparse.Namespace) -> int | None:
    if args.command == "probe-correction":
        return _probe_correction(args)
    if args.command == "sweep":
        return _sweep(args)
    if args.command == "report":
        return _report(args)
    if args.command == "tune":
        return _tune(args)
    if args.command == "study" and args.study == "clinical":
        return _clinical(args)
    return None
