"""Sweep files, variants and the table, run serially (the Dask path: tests/integration)."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from hoh_cosim.errors import ConfigError
from hoh_cosim.study.sweep import (
    Variant,
    load_sweep,
    run_variants,
    set_option,
    table_rows,
    write_table,
)
from tests.integration.test_scenarios import SCENARIOS


def _sweep(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "s.yaml"
    path.write_text(f"scenario: {SCENARIOS / 'release.yaml'}\n" + text, encoding="utf-8")
    return path


def test_grid_times_seeds(tmp_path: Path) -> None:
    sweep = load_sweep(
        _sweep(
            tmp_path,
            "duration_s: 2\nseeds: [1, 2]\nset: {estimator.filter: kalman}\n"
            "grid:\n  controller.translation.slope: [0.01, [0.02, 0.02, 0.01]]\n"
            "  controller.contact_compensation: [true, false]\n",
        )
    )
    assert sweep.name == "s"
    assert sweep.parameters == ("controller.translation.slope", "controller.contact_compensation")
    assert len(sweep.variants) == 8
    first = sweep.variants[0]
    assert first.overrides == (
        "estimator.filter=kalman",
        "controller.translation.slope=0.01",
        "controller.contact_compensation=true",
    )
    assert [v.seed for v in sweep.variants[:2]] == [1, 2]
    assert sweep.variants[7].values == (
        ("controller.translation.slope", [0.02, 0.02, 0.01]),
        ("controller.contact_compensation", False),
    )


def test_random_samples_are_seeded_and_in_range(tmp_path: Path) -> None:
    text = (
        "random:\n  n: 12\n  seed: 7\n  params:\n"
        "    estimator.butterworth.cutoff_hz: {uniform: [2.0, 20.0]}\n"
        "    controller.translation.slope[1]: {log_uniform: [0.001, 0.1]}\n"
        "    estimator.butterworth.order: {integer: [2, 6]}\n"
        "    estimator.filter: {choice: [kalman, one_euro]}\n"
    )
    a = load_sweep(_sweep(tmp_path, text))
    b = load_sweep(_sweep(tmp_path, text))
    assert a.variants == b.variants
    values = [dict(v.values) for v in a.variants]
    assert all(2.0 <= v["estimator.butterworth.cutoff_hz"] <= 20.0 for v in values)
    assert all(0.001 <= v["controller.translation.slope[1]"] <= 0.1 for v in values)
    assert {v["estimator.butterworth.order"] for v in values} <= {2, 3, 4, 5, 6}
    assert {v["estimator.filter"] for v in values} == {"kalman", "one_euro"}
    other = load_sweep(_sweep(tmp_path, text.replace("seed: 7", "seed: 8")))
    assert other.variants != a.variants


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "grid: {controller.nonsense: [1]}\n",
            "s.yaml: grid.controller.nonsense: --set controller.nonsense: unknown parameter",
        ),
        (
            "grid: {estimator.filter: [kalman, bogus]}\n",
            "s.yaml: grid.estimator.filter: --set estimator.filter: expected one of kalman",
        ),
        ("grid: {estimator.filter: []}\n", "s.yaml: grid.estimator.filter: expected a non-empty"),
        (
            "random: {n: 2, params: {x.y: {normal: [0, 1]}}}\n",
            "s.yaml: random.params.x.y.normal: unknown key",
        ),
        (
            "random: {n: 2, params: {controller.translation.slope: {log_uniform: [0, 1]}}}\n",
            "s.yaml: random.params.controller.translation.slope.log_uniform: expected bounds > 0",
        ),
        ("grid: {a.b: [1]}\nrandom: {n: 1}\n", "s.yaml: random: give either grid or random"),
        ("seeds: []\n", "s.yaml: seeds: expected a non-empty list"),
        ("engine: warp\n", "s.yaml: engine: expected one of inprocess, fmu, got 'warp'"),
        ("colour: red\n", "s.yaml: colour: unknown key"),
    ],
)
def test_mistakes_are_one_line_naming_the_key(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_sweep(_sweep(tmp_path, text))
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_a_failed_run_is_a_row_and_the_table_round_trips(tmp_path: Path) -> None:
    good = Variant(
        0,
        str(SCENARIOS / "release.yaml"),
        (set_option("controller.translation.slope", 0.01),),
        (("controller.translation.slope", 0.01),),
        3,
        1.0,
    )
    bad = Variant(
        1, str(tmp_path / "missing.yaml"), (), (("controller.translation.slope", 0.02),), 3, 1.0
    )
    outcomes = run_variants([good, bad], workers=0, progress=False)
    assert [o.status for o in outcomes] == ["ok", "failed"]
    assert "missing.yaml: no such file" in outcomes[1].error
    columns, rows = table_rows(outcomes)
    assert columns[:6] == [
        "run",
        "seed",
        "controller.translation.slope",
        "status",
        "error",
        "wall_s",
    ]
    assert "controller_flags" in columns
    assert "wall_s" not in columns[6:]  # the run's wall time, once
    written = write_table(tmp_path, columns, rows)
    with (tmp_path / "runs.csv").open(encoding="utf-8") as f:
        back = list(csv.DictReader(f))
    assert [r["status"] for r in back] == ["ok", "failed"]
    assert back[0]["seed"] == "3"
    assert back[1]["controller_flags"] == ""
    assert float(back[0]["realtime_factor"]) == outcomes[0].metrics["realtime_factor"]
    if len(written) == 2:
        import pyarrow.parquet as pq

        table = pq.read_table(tmp_path / "runs.parquet").to_pylist()
        assert table[0]["controller.translation.slope"] == 0.01
        assert table[1]["status"] == "failed"
        assert table[0]["realtime_factor"] == outcomes[0].metrics["realtime_factor"]
