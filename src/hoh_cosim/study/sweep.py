"""Sweeps: many variants of a scenario run on Dask, one table row per run.

A sweep file names a scenario and how to vary it:

    name: slope_sweep                  # optional: the file's stem
    scenario: ../scenarios/circles.yaml  # relative to this file
    engine: inprocess                  # or fmu; inprocess is bit-identical and twice as fast
    duration_s: 20                     # optional: instead of the scenario's
    seeds: [1, 2, 3]                   # every variant runs with each (default: the scenario's)
    set:                               # fixed for every run, as --set
      controller.translation.law: deadband_linear
    grid:                              # every combination of these values
      controller.translation.slope: [0.01, 0.0125, 0.015]
      estimator.filter: [kalman, butterworth]
    random:                            # or (not with grid) n seeded random samples
      n: 20
      seed: 7
      params:
        estimator.butterworth.cutoff_hz: {uniform: [2.0, 20.0]}
        estimator.hand_force_kalman.q[1]: {log_uniform: [1.0, 1000.0]}
        estimator.filter: {choice: [kalman, one_euro]}

Every parameter is one `--set` path. Every variant is checked against the scenario before anything
runs, so a misspelt parameter or an impossible value is one error line naming the sweep file and
the key, not a thousand failed rows.

The runs go to a Dask cluster: by default a local one of worker processes on this machine, or an
existing one at `--scheduler tcp://host:port`. Each run is independent (its own components, its own
seeded random streams), so where it ran does not change its numbers: the table equals the serial
one except for wall times. A run that fails is a row with status `failed` and its error; a worker
that dies is retried by Dask, then recorded the same way. The table: `run`, `seed`, one column per
varied parameter, `status`, `error`, `wall_s`, then every metric (vectors as `name[1]`, `name[2]`,
...), as CSV and Parquet.
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import os
import socket
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.errors import ConfigError, HohError
from hoh_cosim.yamlfile import Where, read_yaml

__all__ = [
    "MAX_RUNS",
    "QUIET_CLUSTER",
    "Outcome",
    "RunPool",
    "Sweep",
    "Variant",
    "check_scheduler",
    "load_sweep",
    "run_variant",
    "run_variants",
    "table_rows",
    "write_table",
]

ENGINES = ("inprocess", "fmu")
_TOP_KEYS = ("name", "scenario", "engine", "duration_s", "seeds", "set", "grid", "random")
_DISTRIBUTIONS = ("uniform", "log_uniform", "integer", "choice")
FIXED_COLUMNS = ("run", "seed")
MAX_RUNS = 10_000
"""The most runs a sweep file may ask for (variants times seeds). Each variant is checked against
the scenario before anything runs (10-30 ms a variant) and each run takes seconds: a larger study
is several sweeps. Without a bound, `random: {n: 2147483647}` made its variants until memory ran
out."""
STATUS_COLUMNS = ("status", "error", "wall_s")
QUIET_CLUSTER: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,  # a sample of the running run's stack every 10 ms
    "distributed.admin.tick.interval": "1s",  # each event loop's health check, every 20 ms
    "distributed.admin.system-monitor.interval": "2s",  # CPU, memory and disk, every 500 ms
    "distributed.worker.memory.monitor-interval": "1s",  # the nanny's memory check, every 100 ms
}
"""Dask settings of the local cluster that runs a study: its processes' own periodic work, which
with Dask's defaults took about 9 % of this 2-core machine while two workers stepped (the workers'
event loops, the nannies and the scheduler, measured per thread in
`docs/decisions/0020-studies-on-dask.md`), is made rare. Nothing a run computes depends on them; a
cluster given by `--scheduler` keeps its own."""


@dataclass(frozen=True)
class Variant:
    """One run: the scenario, its `--set` overrides and seed, and what to bring back besides the
    metrics (recorded signals every `keep_every` ticks; the metric set's intermediate data)."""

    index: int
    scenario: str
    overrides: tuple[str, ...] = ()
    values: tuple[tuple[str, Any], ...] = ()  # the varied parameters, for the table
    seed: int | None = None
    duration_s: float | None = None
    engine: str = "inprocess"
    keep: tuple[str, ...] = ()
    keep_every: int = 10
    keep_data: bool = False
    preset: str | None = None  # the estimator's and the controller's (None: the scenario's)


@dataclass
class Outcome:
    """What one run gave: status "ok" or "failed" (then `error` says why)."""

    variant: Variant
    status: str
    seed: int | None = None
    error: str = ""
    wall_s: float = math.nan
    metrics: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    time: np.ndarray | None = None
    signals: dict[str, np.ndarray] = field(default_factory=dict)
    data: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def run_variant(variant: Variant) -> Outcome:
    """Load, run and measure one variant, in whatever process this is; never raises for a run
    that fails (the outcome says so), only for an interrupt."""
    from hoh_cosim.cosim.engines import simulate
    from hoh_cosim.cosim.report import compute_report
    from hoh_cosim.cosim.scenario import load_scenario

    start = time.perf_counter()
    try:
        scenario = load_scenario(
            variant.scenario, variant.overrides, variant.duration_s, variant.seed, variant.preset
        )
        rec = simulate(scenario, variant.engine, progress=False)
        report = compute_report(scenario, rec)
    except Exception as exc:
        text = str(exc) if isinstance(exc, HohError) else f"{type(exc).__name__}: {exc}"
        return Outcome(
            variant,
            "failed",
            seed=variant.seed,
            error=" ".join(text.split()),
            wall_s=time.perf_counter() - start,
        )
    rows = slice(None, None, variant.keep_every)
    signals = {name: rec[name][rows].copy() for name in variant.keep}
    return Outcome(
        variant,
        "ok",
        seed=scenario.seed,
        wall_s=time.perf_counter() - start,
        metrics=dict(report.metrics),
        notes=list(report.notes),
        time=rec.time[rows].copy() if variant.keep else None,
        signals=signals,
        data=dict(report.data) if variant.keep_data else {},
    )


class _Bar:
    """A one-line count of finished runs on a terminal."""

    def __init__(self, label: str, total: int, enabled: bool) -> None:
        self.label, self.total = label, total
        self.enabled = enabled and sys.stderr.isatty()
        self.start = time.perf_counter()
        self.done = self.failed = 0

    def update(self, outcome: Outcome) -> None:
        self.done += 1
        self.failed += not outcome.ok
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.start
        eta = elapsed / self.done * (self.total - self.done)
        bar = "#" * int(30 * self.done / self.total)
        failed = f", {self.failed} failed" if self.failed else ""
        sys.stderr.write(
            f"\r{self.label} [{bar:<30}] {self.done}/{self.total} runs{failed}, {eta:.0f} s left "
        )
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.done:
            sys.stderr.write("\r" + " " * 79 + "\r")
            sys.stderr.flush()


def _failed(variant: Variant, exc: BaseException) -> Outcome:
    text = " ".join(f"{type(exc).__name__}: {exc}".split())
    return Outcome(variant, "failed", seed=variant.seed, error=text)


def run_variants(
    variants: Sequence[Variant],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    label: str = "sweep",
    on_outcome: Callable[[Outcome], None] | None = None,
) -> list[Outcome]:
    """Run every variant, in `variants` order: serially in this process when `workers` is 0 and no
    scheduler is given; else on the Dask cluster at `scheduler`, or on a local cluster of `workers`
    worker processes (default: one per core), one thread each (the runs are pure Python)."""
    if not variants:
        return []
    with RunPool(
        workers=workers,
        scheduler=scheduler,
        progress=progress,
        label=label,
        on_outcome=on_outcome,
        expected=len(variants),
    ) as pool:
        pool.submit(variants)
        return pool.results()


class RunPool:
    """`run_variants` in batches: runs submitted now start at once on the cluster (longest first
    among those waiting), while the caller computes what the next batch depends on; `results()`
    waits for every run submitted and gives their outcomes in submission order.

        with RunPool(workers=2, label="report") as pool:
            pool.submit(independent)
            ...                      # e.g. the analysis that picks the other runs
            pool.submit(dependent)
            outcomes = pool.results()

    Serially (`workers` 0, no scheduler) the runs go in `results()`, in order, in this process.
    `expected`, the number of runs if known, keeps a local cluster from starting more workers than
    runs."""

    def __init__(
        self,
        *,
        workers: int | None = None,
        scheduler: str | None = None,
        progress: bool = True,
        label: str = "sweep",
        on_outcome: Callable[[Outcome], None] | None = None,
        expected: int | None = None,
    ) -> None:
        self.workers, self.scheduler, self.expected = workers, scheduler, expected
        self.on_outcome = on_outcome
        self.serial = scheduler is None and workers == 0
        self.bar = _Bar(label, 0, progress)
        self.variants: list[Variant] = []
        self.futures: dict[Any, int] = {}
        self.cluster: Any = None
        self.client: Any = None
        self._config: Any = None

    def __enter__(self) -> RunPool:
        if not self.serial:
            try:
                self._connect()
            except BaseException:
                self.close()
                raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _connect(self) -> None:
        import logging

        import dask.config
        from distributed import Client, LocalCluster

        if self.scheduler is None:
            n = self.workers if self.workers is not None else (os.cpu_count() or 1)
            if n < 1:
                raise ConfigError(f"--workers: expected an integer >= 0, got {n}")
            # the scheduler reads them here, the nannies hand them to their workers
            self._config = dask.config.set(QUIET_CLUSTER)
            self.cluster = LocalCluster(
                n_workers=min(n, self.expected) if self.expected else n,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=":0",  # a free port: never clash with a running cluster
                silence_logs=logging.ERROR,
            )
            self.client = Client(self.cluster)
        else:
            check_scheduler(self.scheduler)
            try:
                _refused(self.scheduler)
                self.client = Client(self.scheduler, timeout=10)
            except (OSError, TimeoutError, ValueError) as exc:
                raise ConfigError(
                    f"--scheduler {self.scheduler}: cannot reach a Dask scheduler there ({exc})"
                ) from None

    def submit(self, variants: Sequence[Variant]) -> None:
        """Start `variants` (on the cluster; serially, they wait for `results()`)."""
        first = len(self.variants)
        self.variants.extend(variants)
        self.bar.total += len(variants)
        if self.serial or not variants:
            return
        # longest first: the last runs to finish are short ones, not a long one on one worker
        # while the others idle (a report's 272 s calibration runs among 30 s ones)
        length = _simulated_seconds(variants)
        for i, v in enumerate(variants):
            future = self.client.submit(run_variant, v, pure=False, priority=length[i])
            self.futures[future] = first + i

    def results(self) -> list[Outcome]:
        """Every submitted run's outcome, in submission order (waits for the runs)."""
        outcomes: dict[int, Outcome] = {}

        def finish(i: int, outcome: Outcome) -> None:
            outcomes[i] = outcome
            self.bar.update(outcome)
            if self.on_outcome is not None:
                self.on_outcome(outcome)

        if self.serial:
            for i, variant in enumerate(self.variants):
                finish(i, run_variant(variant))
        else:
            from distributed import as_completed

            for future in as_completed(list(self.futures)):
                i = self.futures[future]
                try:
                    outcome = future.result()
                except Exception as exc:  # a worker died with it, or it could not be sent
                    outcome = _failed(self.variants[i], exc)
                finish(i, outcome)
        return [outcomes[i] for i in range(len(self.variants))]

    def close(self) -> None:
        self.bar.close()
        try:
            if self.client is not None:
                self.client.close()
        finally:
            self.client = None
            try:
                if self.cluster is not None:
                    self.cluster.close()
                    self.cluster = None
            finally:
                if self._config is not None:
                    self._config.__exit__(None, None, None)
                    self._config = None


def _simulated_seconds(variants: Sequence[Variant]) -> list[int]:
    """Each variant's simulated milliseconds (its duration, else its scenario's; an FMU run counted
    twice, as it steps about half as fast), as the priority of its run."""
    from hoh_cosim.cosim.scenario import load_scenario

    durations: dict[str, float] = {}
    out = []
    for v in variants:
        duration = v.duration_s
        if duration is None:
            if v.scenario not in durations:
                try:
                    durations[v.scenario] = load_scenario(v.scenario).duration_s
                except (HohError, OSError):  # the run itself will say what is wrong with it
                    durations[v.scenario] = 0.0
            duration = durations[v.scenario]
        out.append(round(1e3 * duration * (2.0 if v.engine == "fmu" else 1.0)))
    return out


def check_scheduler(scheduler: str) -> None:
    """Refuse an address Dask cannot read (`--scheduler bogus`) with one line, before any run:
    Dask's own error is a traceback from deep inside its client."""
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(scheduler, strict=True)
        if scheme in ("tcp", "tls", "ws", "wss"):
            parse_host_port(location)
    except (ValueError, TypeError) as exc:
        raise ConfigError(
            f"--scheduler {scheduler}: expected a Dask scheduler's address like "
            f"tcp://10.0.0.5:8786 ({exc})"
        ) from None


def _refused(scheduler: str) -> None:
    """Raise OSError at once when nothing listens at a tcp:// address: Dask's client would retry
    it for its whole timeout. Other addresses, and a port that answers, are left to Dask."""
    from urllib.parse import urlsplit

    parts = urlsplit(scheduler)
    if parts.scheme != "tcp" or not parts.hostname or parts.port is None:
        return
    with socket.create_connection((parts.hostname, parts.port), timeout=5.0):
        pass


# -- sweep files ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Sweep:
    name: str
    path: Path
    scenario: Path
    engine: str
    duration_s: float | None
    variants: tuple[Variant, ...]
    parameters: tuple[str, ...]  # the varied ones, in column order


def _sample(rng: np.random.Generator, spec: Any, where: str, w: Where) -> Any:
    spec = w.mapping(spec, _DISTRIBUTIONS, where)
    if len(spec) != 1:
        raise w.error(where, f"expected one of {', '.join(_DISTRIBUTIONS)}, got {dict(spec)!r}")
    ((kind, arg),) = spec.items()
    if kind == "choice":
        if not isinstance(arg, list) or not arg:
            raise w.error(f"{where}.choice", f"expected a non-empty list, got {arg!r}")
        return arg[int(rng.integers(len(arg)))]
    if not (isinstance(arg, list) and len(arg) == 2):
        raise w.error(f"{where}.{kind}", f"expected [low, high], got {arg!r}")
    low = w.number(arg[0], f"{where}.{kind}[0]")
    high = w.number(arg[1], f"{where}.{kind}[1]")
    if high < low:
        raise w.error(f"{where}.{kind}", f"expected low <= high, got [{low:g}, {high:g}]")
    if kind == "uniform":
        return float(rng.uniform(low, high))
    if kind == "integer":
        if low != int(low) or high != int(high):
            raise w.error(f"{where}.integer", f"expected integer bounds, got {arg!r}")
        return int(rng.integers(int(low), int(high) + 1))
    if low <= 0:
        raise w.error(f"{where}.log_uniform", f"expected bounds > 0, got {arg!r}")
    return float(math.exp(rng.uniform(math.log(low), math.log(high))))


def _value_text(value: Any) -> str:
    """A value as `--set` reads it back (YAML flow style, floats exact)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_value_text(v) for v in value) + "]"
    return str(value)


def set_option(path: str, value: Any) -> str:
    """`component.parameter=value` for `--set` (and `Variant.overrides`)."""
    return f"{path}={_value_text(value)}"


def _check(
    scenario: Path,
    base: tuple[str, ...],
    point: Mapping[str, Any],
    duration: float | None,
    where_of: Mapping[str, str],
    w: Where,
) -> None:
    """Load the scenario with one variant's overrides; a mistake names the key that made it."""
    from hoh_cosim.cosim.scenario import load_scenario

    overrides = base
    for key, value in point.items():
        overrides = (*overrides, set_option(key, value))
        try:
            load_scenario(scenario, overrides, duration)
        except ConfigError as exc:
            raise w.error(where_of[key], str(exc)) from None


def _check_runs(points: int, seeds: int, where: str, w: Where) -> None:
    """Refuse a sweep of more than `MAX_RUNS` runs before its variants are made."""
    if points * seeds > MAX_RUNS:
        raise w.error(
            where,
            f"{points} variants x {seeds} seeds = {points * seeds} runs, more than {MAX_RUNS}: "
            "split the sweep",
        )


def _keys(value: Any) -> list[Any]:
    """The keys of a mapping whose keys are all allowed (any other value has none)."""
    return list(value) if isinstance(value, Mapping) else []


def load_sweep(path: str | Path, engine: str | None = None) -> Sweep:
    """Read a sweep file and check every variant against its scenario."""
    from hoh_cosim.cosim.scenario import load_scenario

    path = Path(path)
    w = Where(path)
    raw = w.mapping(read_yaml(path), _TOP_KEYS, "")
    if "scenario" not in raw:
        raise w.error("scenario", "missing")
    name = w.string(raw.get("name", path.stem), "name")
    scenario = (path.parent / w.string(raw["scenario"], "scenario")).resolve()
    if engine is None:
        engine = w.string(raw.get("engine", "inprocess"), "engine", choices=ENGINES)
    duration = raw.get("duration_s")
    if duration is not None:
        duration = w.number(duration, "duration_s", positive=True)
    seeds_raw = raw.get("seeds", [None])
    if not isinstance(seeds_raw, list) or not seeds_raw:
        raise w.error("seeds", f"expected a non-empty list of integers, got {seeds_raw!r}")
    seeds = [None if s is None else w.integer(s, f"seeds[{i}]") for i, s in enumerate(seeds_raw)]
    fixed = w.mapping(raw.get("set") or {}, _keys(raw.get("set")), "set")
    if "grid" in raw and "random" in raw:
        raise w.error("random", "give either grid or random, not both")

    points: list[dict[str, Any]]
    if "grid" in raw:
        grid = w.mapping(raw["grid"], _keys(raw["grid"]), "grid")
        for key, values in grid.items():
            if not isinstance(values, list) or not values:
                raise w.error(f"grid.{key}", f"expected a non-empty list of values, got {values!r}")
        keys = list(grid)
        _check_runs(math.prod(len(values) for values in grid.values()), len(seeds), "grid", w)
        points = [
            dict(zip(keys, combo, strict=True)) for combo in itertools.product(*grid.values())
        ]
        where_of = {key: f"grid.{key}" for key in keys}
    elif "random" in raw:
        rand = w.mapping(raw["random"], ("n", "seed", "params"), "random")
        n = w.integer(rand.get("n"), "random.n", low=1)
        _check_runs(n, len(seeds), "random.n", w)
        rng = np.random.default_rng(w.integer(rand.get("seed", 0), "random.seed"))
        params = w.mapping(rand.get("params"), _keys(rand.get("params")), "random.params")
        if not params:
            raise w.error("random.params", "expected at least one parameter")
        keys = list(params)
        points = [
            {key: _sample(rng, params[key], f"random.params.{key}", w) for key in keys}
            for _ in range(n)
        ]
        where_of = {key: f"random.params.{key}" for key in keys}
    else:
        keys, points, where_of = [], [{}], {}

    base = tuple(set_option(k, v) for k, v in fixed.items())
    try:
        load_scenario(scenario, base, duration)
    except ConfigError as exc:
        raise w.error("scenario" if not base else "set", str(exc)) from None
    variants = []
    checked: set[tuple[str, ...]] = {base}
    for point in points:
        overrides = base + tuple(set_option(k, v) for k, v in point.items())
        if overrides not in checked:
            _check(scenario, base, point, duration, where_of, w)
            checked.add(overrides)
        for seed in seeds:
            variants.append(
                Variant(
                    len(variants),
                    str(scenario),
                    overrides,
                    tuple(point.items()),
                    seed,
                    duration,
                    engine,
                )
            )
    return Sweep(name, path, scenario, engine, duration, tuple(variants), tuple(keys))


# -- the table -----------------------------------------------------------------------------------


def _cell(value: Any) -> Any:
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, list | tuple | dict):
        return json.dumps(value)
    return value


def table_rows(outcomes: Iterable[Outcome]) -> tuple[list[str], list[dict[str, Any]]]:
    """The sweep's table: columns in order and one row (column -> value) per run."""
    rows: list[dict[str, Any]] = []
    params: dict[str, None] = {}
    metrics: dict[str, None] = {}
    for outcome in outcomes:
        row: dict[str, Any] = {"run": outcome.variant.index, "seed": outcome.seed}
        for key, value in outcome.variant.values:
            params[key] = None
            row[key] = _cell(value)
        row.update(status=outcome.status, error=outcome.error, wall_s=outcome.wall_s)
        for key, value in outcome.metrics.items():
            if key == "wall_s":  # the simulation's share of the run's own wall_s
                continue
            if isinstance(value, list | tuple | np.ndarray):
                for i, v in enumerate(value):
                    name = f"{key}[{i + 1}]"
                    metrics[name] = None
                    row[name] = _cell(v)
            else:
                metrics[key] = None
                row[key] = _cell(value)
        rows.append(row)
    columns = [*FIXED_COLUMNS, *params, *STATUS_COLUMNS, *metrics]
    return columns, rows


def csv_text(columns: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        cells = []
        for column in columns:
            value = row.get(column)
            if value is None or (isinstance(value, float) and math.isnan(value)):
                cells.append("")
            elif isinstance(value, float):
                cells.append(repr(value))
            else:
                cells.append(value)
        writer.writerow(cells)
    return buffer.getvalue()


def _parquet(path: Path, columns: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = {}
    for column in columns:
        values = [row.get(column) for row in rows]
        kinds = {type(v) for v in values if v is not None}
        if kinds <= {int} and kinds:
            arrays[column] = pa.array(values, type=pa.int64())
        elif kinds <= {int, float} and kinds:
            arrays[column] = pa.array(
                [None if v is None else float(v) for v in values], type=pa.float64()
            )
        elif kinds <= {bool} and kinds:
            arrays[column] = pa.array(values, type=pa.bool_())
        else:
            arrays[column] = pa.array(
                [None if v is None else str(v) for v in values], type=pa.string()
            )
    pq.write_table(pa.table(arrays), path)


def write_table(
    directory: Path, columns: Sequence[str], rows: Sequence[Mapping[str, Any]]
) -> list[Path]:
    """runs.csv and runs.parquet into `directory`."""
    written = [directory / "runs.csv", directory / "runs.parquet"]
    written[0].write_text(csv_text(columns, rows), encoding="utf-8")
    _parquet(written[1], columns, rows)
    return written
