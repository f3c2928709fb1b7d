"""One scenario run from the file to the results directory (DESIGN.md §6).

    DIR/signals.parquet time and every recorded signal, one column per element (component.port[i]),
                        and a bit field's flags by name beside it (controller.status_text);
                        DIR/signals.csv with --format csv, the same columns
    DIR/summary.json    scenario, engine, seed, duration, the preset and every value that differs
                        from it, metrics (with wall time and real-time factor), notes
    DIR/*.png           the scenario's plots
    DIR/...             whatever else the metric set produces (poses.csv, calibration.json)

The directory is assembled beside its destination and moved into place only when everything is
written: a run that fails leaves no directory behind that looks like a result, and an earlier result
in the same place is replaced whole, never mixed with the new one. A directory that is not a run's
(it has files but no summary.json) is never replaced.
"""

from __future__ import annotations

import enum
import io
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from hoh_cosim import __version__
from hoh_cosim.cosim import EXTERNAL_ENGINES
from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.recording import Recording
from hoh_cosim.cosim.report import Report, compute_report
from hoh_cosim.cosim.scenario import Scenario, load_scenario
from hoh_cosim.errors import ConfigError
from hoh_cosim.results import FORMATS, check_out_dir, replace_dir

__all__ = [
    "RunResult",
    "RunWatch",
    "jsonable",
    "run_scenario",
    "signal_columns",
    "summary_of",
    "write_results",
    "write_signals",
]


@dataclass
class RunResult:
    scenario: Scenario
    recording: Recording
    report: Report
    out: Path
    summary: dict[str, Any]


class RunWatch(Protocol):
    """Something that watches a run as it goes (the view, `hoh_cosim.view.cosim`): made once the
    scenario is loaded and before anything runs (so that it can refuse with one line), told of
    every tick of our master (`engines.simulate`'s observer; never for an external engine, which
    steps on its own), then given the whole recording once the results are written, or told that
    the run failed."""

    def tick(self, k: int, t: float, outputs: np.ndarray) -> None: ...
    def done(self, rec: Recording) -> None: ...
    def abandon(self) -> None: ...


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
            # the preset, and every value of the estimator's and the controller's parameters
            # that differs from it (the scenario's own and --set)
            "preset": None if scenario.preset is None else scenario.preset.label,
            "preset_changes": scenario.preset_changes(),
            "metrics": report.metrics,  # with the run's wall_s and realtime_factor
            "notes": report.notes,
            "hoh_cosim_version": __version__,
        }
    )


def flag_names(flags: type[enum.IntFlag] | type[enum.IntEnum], value: float) -> str:
    """A bit field's set flags by name, `A|B` ("ok" when none is set); an enumeration's value by
    its name."""
    if not issubclass(flags, enum.IntFlag):
        return flags(int(value)).name
    bits = int(value)
    return "|".join(f.name for f in flags if f.name and f.value & bits) or "ok"


def signal_columns(scenario: Scenario, rec: Recording) -> dict[str, np.ndarray]:
    """The recorded signals as named columns: `time`, then one per element (`component.port[i]`),
    and beside a bit field (a port with `flags`) its flags by name (`component.port_text`)."""
    rows = slice(None, None, scenario.record_every)
    columns: dict[str, np.ndarray] = {"time": rec.time[rows]}
    for signal in scenario.record:
        values = rec[signal][rows]
        for i, name in enumerate(rec.element_names[signal]):
            columns[name] = values[:, i]
        component, _, port_name = signal.partition(".")
        port = next(p for p in scenario.components[component].outputs if p.name == port_name)
        if port.flags is not None:
            codes = values[:, 0]
            text = {v: flag_names(port.flags, v) for v in np.unique(codes)}
            columns[f"{signal}_text"] = np.array([text[v] for v in codes.tolist()], dtype=object)
    return columns


def _write_csv(path: Path, columns: dict[str, np.ndarray]) -> None:
    numeric = [name for name, v in columns.items() if v.dtype != object]
    text = [name for name, v in columns.items() if v.dtype == object]
    buffer = io.StringIO()
    np.savetxt(buffer, np.column_stack([columns[n] for n in numeric]), fmt="%.10g", delimiter=",")
    lines = buffer.getvalue().splitlines()
    if text:
        extra = zip(*(columns[n] for n in text), strict=True)
        lines = [",".join((line, *words)) for line, words in zip(lines, extra, strict=True)]
    with path.open("w", encoding="utf-8", newline="\n") as f:
        f.write(",".join(numeric + text) + "\n")
        f.write("\n".join(lines) + "\n")


def _write_parquet(path: Path, columns: dict[str, np.ndarray]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table(
        {
            name: pa.array(v, type=pa.string()).dictionary_encode() if v.dtype == object else v
            for name, v in columns.items()
        }
    )
    # float columns split into byte streams compress about a third better under zstd (circles, 30 s:
    # 9.6 MB as CSV, 3.3 MB plain, 2.9 MB split; measured with pyarrow 26)
    floats = [name for name, v in columns.items() if v.dtype != object]
    pq.write_table(
        table, path, compression="zstd", use_dictionary=False, use_byte_stream_split=floats
    )


def write_signals(directory: Path, scenario: Scenario, rec: Recording, fmt: str) -> Path:
    """`signals.parquet` or `signals.csv` in `directory`; the path written."""
    if fmt not in FORMATS:
        raise ConfigError(f"--format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    path = directory / f"signals.{fmt}"
    columns = signal_columns(scenario, rec)
    (_write_parquet if fmt == "parquet" else _write_csv)(path, columns)
    return path


def write_results(
    out: Path,
    scenario: Scenario,
    rec: Recording,
    report: Report,
    summary: dict,
    plots: dict[str, bytes],
    fmt: str = "parquet",
) -> None:
    """Write a run's files into `out` through `replace_dir`; summary.json last, since its presence
    says the directory is complete."""

    def fill(staging: Path) -> None:
        write_signals(staging, scenario, rec, fmt)
        for name, text in report.files.items():
            (staging / name).write_text(text, encoding="utf-8")
        for name, png in plots.items():
            (staging / name).write_bytes(png)
        (staging / "summary.json").write_text(
            json.dumps(summary, indent=2, allow_nan=False) + "\n", encoding="utf-8"
        )

    replace_dir(out, fill, what="run")


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
    fmt: str = "parquet",
    preset: str | None = None,
    fmi: int = 2,
    watch: Callable[[Scenario], RunWatch] | None = None,
) -> RunResult:
    """Load, run, measure and write one scenario; `out` defaults to runs/<scenario name>, the
    signals as `fmt` ("parquet" or "csv"), `preset` the estimator's and the controller's
    (`hoh_cosim.presets`; default: the scenario's), `fmi` the FMI version of the fmu engine's
    FMUs, `watch` what watches the run (`RunWatch`, made from the loaded scenario)."""
    if fmt not in FORMATS:
        raise ConfigError(f"--format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    scenario = load_scenario(path, overrides, duration_s, seed, preset)
    out_dir = Path(out) if out is not None else Path("runs") / scenario.name
    check_out_dir(out_dir)
    watcher = watch(scenario) if watch is not None else None
    try:
        rec = simulate(
            scenario,
            engine,
            progress=progress,
            coupling=coupling,
            fmi=fmi,
            observer=None if watcher is None or engine in EXTERNAL_ENGINES else watcher.tick,
        )
        report = compute_report(scenario, rec)
        summary = summary_of(scenario, rec, report, overrides)
        images: dict[str, bytes] = {}
        if plots:
            from hoh_cosim.cosim.plots import render_plots

            images = render_plots(scenario, rec, report)
        write_results(out_dir, scenario, rec, report, summary, images, fmt)
        if watcher is not None:
            watcher.done(rec)
    except BaseException:
        if watcher is not None:
            watcher.abandon()
        raise
    return RunResult(scenario, rec, report, out_dir, summary)
