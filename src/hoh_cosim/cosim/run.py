"""One scenario run from the file to the results directory (DESIGN.md §6).

    DIR/signals.csv     time and every recorded signal, one column per element (component.port[i])
    DIR/summary.json    scenario, engine, seed, duration, wall time, real-time factor, metrics, notes
    DIR/*.png           the scenario's plots
    DIR/...             whatever else the metric set produces (poses.csv, calibration.json)

The directory is assembled beside its destination and moved into place only when everything is
written: a run that fails leaves no directory behind that looks like a result, and an earlier result
in the same place is replaced whole, never mixed with the new one. A directory that is not a run's
(it has files but no summary.json) is never replaced.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim import __version__
from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.recording import Recording
from hoh_cosim.cosim.report import Report, compute_report
from hoh_cosim.cosim.scenario import Scenario, load_scenario
from hoh_cosim.errors import ConfigError

__all__ = [
    "RunResult",
    "check_out_dir",
    "jsonable",
    "replace_dir",
    "run_scenario",
    "summary_of",
    "write_results",
]


@dataclass
class RunResult:
    scenario: Scenario
    recording: Recording
    report: Report
    out: Path
    summary: dict[str, Any]


def check_out_dir(out: Path, marker: str = "summary.json", what: str = "run") -> None:
    """Refuse, before anything runs, a destination that a result must not replace: one that is not
    a directory, or a non-empty directory without `marker` (so not an earlier result)."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out}: exists and is not a directory")
    if out.is_dir() and any(out.iterdir()) and not (out / marker).is_file():
        raise ConfigError(
            f"--out {out}: exists, is not empty and holds no {marker}, so it is not a "
            f"hoh-cosim {what} directory; choose another"
        )


def jsonable(value: Any) -> Any:
    """Plain JSON: non-finite floats become null (JSON has no NaN)."""
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def summary_of(
    scenario: Scenario, rec: Recording, report: Report, overrides: Sequence[str]
) -> dict:
    return jsonable(
        {
            "scenario": scenario.name,
            "file": str(scenario.path),
            "description": scenario.description,
            "engine": rec.engine,
            "coupling": rec.coupling,
            "seed": scenario.seed,
            "duration_s": scenario.duration_s,
            "dt_s": scenario.dt_s,
            "overrides": list(overrides),
            "wall_s": rec.wall_s,
            "realtime_factor": report.metrics.get("realtime_factor"),
            "metrics": report.metrics,
            "notes": report.notes,
            "hoh_cosim_version": __version__,
        }
    )


def _signals_csv(path: Path, scenario: Scenario, rec: Recording) -> None:
    rows = slice(None, None, scenario.record_every)
    header = ["time"]
    blocks = [rec.time[rows, None]]
    for signal in scenario.record:
        header += rec.element_names[signal]
        blocks.append(rec[signal][rows])
    data = np.hstack(blocks)
    with path.open("w", encoding="utf-8", newline="\n") as f:
        f.write(",".join(header) + "\n")
        np.savetxt(f, data, fmt="%.10g", delimiter=",")


def replace_dir(out: Path, fill: Callable[[Path], None]) -> None:
    """Call `fill(staging)` on an empty directory beside `out`, then move it into place in one
    rename: a failure leaves no half-written result, and an earlier one at `out` is replaced whole
    (or put back if the move fails)."""
    out = out.absolute()
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    old: Path | None = None
    try:
        fill(staging)
        os.chmod(staging, 0o755)
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old.", dir=out.parent))
            out.rename(old / out.name)
        staging.rename(out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        if old is not None and not out.exists():
            (old / out.name).rename(out)  # put the earlier result back
        raise
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


def write_results(
    out: Path,
    scenario: Scenario,
    rec: Recording,
    report: Report,
    summary: dict,
    plots: dict[str, bytes],
) -> None:
    """Write a run's files into `out` through `replace_dir`; summary.json last, since its presence
    says the directory is complete."""

    def fill(staging: Path) -> None:
        _signals_csv(staging / "signals.csv", scenario, rec)
        for name, text in report.files.items():
            (staging / name).write_text(text, encoding="utf-8")
        for name, png in plots.items():
            (staging / name).write_bytes(png)
        (staging / "summary.json").write_text(
            json.dumps(summary, indent=2, allow_nan=False) + "\n", encoding="utf-8"
        )

    replace_dir(out, fill)


def run_scenario(
    path: str | Path,
    *,
    out: str | Path | None = None,
    engine: str = "fmu",
    coupling: str = "gauss-seidel",
    duration_s: float | None = None,
    seed: int | None = None,
    overrides: Sequence[str] = (),
    progress: bool = True,
    plots: bool = True,
) -> RunResult:
    """Load, run, measure and write one scenario; `out` defaults to runs/<scenario name>."""
    scenario = load_scenario(path, overrides, duration_s, seed)
    out_dir = Path(out) if out is not None else Path("runs") / scenario.name
    check_out_dir(out_dir)
    rec = simulate(scenario, engine, progress=progress, coupling=coupling)
    report = compute_report(scenario, rec)
    summary = summary_of(scenario, rec, report, overrides)
    images: dict[str, bytes] = {}
    if plots:
        from hoh_cosim.cosim.plots import render_plots

        images = render_plots(scenario, rec, report)
    write_results(out_dir, scenario, rec, report, summary, images)
    return RunResult(scenario, rec, report, out_dir, summary)
