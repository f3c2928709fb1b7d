"""How long a run's plots take: matplotlib's import, then `render_plots` for each scenario.

    python benchmarks/plots_speed.py [--scenarios circles static_noise ...] [--duration S]
                                     [--repeats 3] [--plots FILE]

Each scenario (`scenarios/NAME.yaml`, its own duration unless `--duration`) is simulated once with
the in-process engine, untimed. Then, `--repeats` times, a fresh Python process loads that recording
and measures what `hoh-cosim` pays after a run: the import of matplotlib's `Figure` and Agg canvas
(what the plots use), the first `render_plots` (fonts loaded, first text laid out; wall-clock and
this process's CPU time, which other load on the machine disturbs less), and one more
`render_plots` in the same process (warm). The best of the repeats is reported (the machine's other
load only ever slows a run down). `--plots FILE` times another version of `plots.py` instead of the
installed one, e.g. `git show HEAD~1:src/hoh_cosim/cosim/plots.py > /tmp/old.py`.

Target on the 2-core reference machine: circles (30 s, 30 001 rows per signal) renders in under
0.5 s, the matplotlib import not counted (it is paid once per process, and also by anything else
that plots). The last line is the figures as one JSON object.
"""

from __future__ import annotations

import argparse
import json
import pickle
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SCENARIOS = (
    "circles",
    "static_noise",
    "gravity_calibration",
    "contact_scan",
    "release",
    "teleecho_slide",
    "teleecho_slide_ur5",
    "probe_data",
)


def child(recording: Path, plots: str | None) -> None:
    """In a fresh process: time the import, the first and a warm `render_plots`; print JSON."""
    with recording.open("rb") as f:
        scenario, rec, report = pickle.load(f)
    if plots:
        import importlib.util

        spec = importlib.util.spec_from_file_location("plots_under_test", plots)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        render_plots = module.render_plots
    else:
        from hoh_cosim.cosim.plots import render_plots
    preloaded = "matplotlib" in sys.modules
    start = time.perf_counter()
    import matplotlib.backends.backend_agg
    import matplotlib.figure  # noqa: F401

    imported, cpu = time.perf_counter(), time.process_time()
    images = render_plots(scenario, rec, report)
    first, first_cpu = time.perf_counter(), time.process_time() - cpu
    render_plots(scenario, rec, report)
    warm = time.perf_counter() - first
    result = {
        "import_s": imported - start,
        "first_s": first - imported,
        "first_cpu_s": first_cpu,
        "warm_s": warm,
        "preloaded": preloaded,
        "rows": len(rec.time),
        "images": sorted(images),
        "bytes": sum(len(b) for b in images.values()),
    }
    print(json.dumps(result))


def record(name: str, duration: float | None, folder: Path) -> Path:
    from hoh_cosim.cosim.engines import simulate
    from hoh_cosim.cosim.report import compute_report
    from hoh_cosim.cosim.scenario import load_scenario

    scenario = load_scenario(ROOT / "scenarios" / f"{name}.yaml", (), duration, None)
    rec = simulate(scenario, "inprocess", progress=False)
    report = compute_report(scenario, rec)
    path = folder / f"{name}.pkl"
    with path.open("wb") as f:
        pickle.dump((scenario, rec, report), f)
    return path


def measure(path: Path, repeats: int, plots: str | None) -> dict:
    runs = []
    for _ in range(repeats):
        command = [sys.executable, __file__, "--child", str(path)]
        if plots:
            command += ["--plots", plots]
        out = subprocess.run(command, capture_output=True, text=True, timeout=600)
        if out.returncode != 0:
            raise SystemExit(f"{path.stem}: the timing process failed:\n{out.stderr}")
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    best = {
        key: min(r[key] for r in runs) for key in ("import_s", "first_s", "first_cpu_s", "warm_s")
    }
    return {**runs[0], **best}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=DEFAULT_SCENARIOS, metavar="NAME")
    parser.add_argument("--duration", type=float, default=None, help="[s] instead of each file's")
    parser.add_argument("--repeats", type=int, default=3, help="fresh processes; the best counts")
    parser.add_argument("--plots", default=None, help="time this plots.py instead")
    parser.add_argument("--child", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        child(args.child, args.plots)
        return 0

    results = {}
    with tempfile.TemporaryDirectory(prefix="hoh-plots-bench-") as tmp:
        for name in args.scenarios:
            results[name] = measure(
                record(name, args.duration, Path(tmp)), args.repeats, args.plots
            )

    print(f"python {platform.python_version()} on {platform.machine()}, best of {args.repeats}")
    print(f"plots: {args.plots or 'hoh_cosim.cosim.plots'}")
    imports = min(r["import_s"] for r in results.values())
    print(f"matplotlib import (Figure + Agg canvas), fresh process: {imports:.3f} s")
    print(
        f"{'scenario':22s} {'rows':>7s} {'first [s]':>10s} {'(cpu)':>6s} {'warm [s]':>9s}  images"
    )
    for name, r in results.items():
        print(
            f"{name:22s} {r['rows']:7d} {r['first_s']:10.3f} {r['first_cpu_s']:6.3f} "
            f"{r['warm_s']:9.3f}  "
            f"{', '.join(r['images'])} ({r['bytes'] // 1024} KiB)"
        )
    if "circles" in results:
        print("target: circles 'first' < 0.5 s (the import not counted)")
    figures = {"repeats": args.repeats, "matplotlib_import_s": round(imports, 4)}
    for name, r in results.items():
        figures[f"{name}_rows"] = r["rows"]
        figures[f"{name}_render_s"] = round(r["first_s"], 4)
        figures[f"{name}_render_cpu_s"] = round(r["first_cpu_s"], 4)
        figures[f"{name}_render_warm_s"] = round(r["warm_s"], 4)
        figures[f"{name}_images"] = len(r["images"])
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
