"""`hoh-cosim sweep` on a real Dask scheduler and two workers on loopback, checked against the same
runs done serially; `hoh-cosim tune` end to end."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from hoh_cosim.cli import main
from hoh_cosim.study.sweep import QUIET_CLUSTER, RunPool, Variant, run_variants
from tests.integration.test_scenarios import SCENARIOS

DASK = Path(sys.executable).parent / "dask"

# one worker runs this module (tests/xdist_groups.py): one Dask cluster for the module
pytestmark = pytest.mark.xdist_group(__name__)


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A Dask scheduler on 127.0.0.1 and two single-threaded worker processes, as a lab would run
    them on its machines."""
    folder = tmp_path_factory.mktemp("dask")
    info = folder / "scheduler.json"
    env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    procs = [
        subprocess.Popen(
            [
                str(DASK),
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--dashboard-address",
                ":0",
                "--scheduler-file",
                str(info),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            cwd=folder,
        )
    ]
    try:
        deadline = time.monotonic() + 60
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert info.exists(), "the Dask scheduler did not start"
        address = json.loads(info.read_text())["address"]
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        str(DASK),
                        "worker",
                        address,
                        "--nthreads",
                        "1",
                        "--nworkers",
                        "1",
                        "--no-nanny",  # one process each, which stops at once on SIGTERM
                        "--host",
                        "127.0.0.1",
                        "--no-dashboard",
                    ],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    env=env,
                    cwd=folder,
                )
            )
        from distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
        yield address
    finally:
        # the workers first and one by one, while the scheduler still answers their goodbye (a
        # worker whose scheduler is gone retries it past any wait); every process reaped
        for p in reversed(procs):
            p.terminate()
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


SWEEP = """\
name: slopes
scenario: {scenario}
duration_s: 7.5
seeds: [1, 4]
grid:
  controller.translation.slope: [0.008, 0.016]
  estimator.filter: [kalman, butterworth]
"""


def _table(path: Path) -> list[dict[str, str]]:
    with path.open(encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_the_cluster_gives_the_serial_table(
    scheduler: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sweep = tmp_path / "slopes.yaml"
    sweep.write_text(SWEEP.format(scenario=SCENARIOS / "release.yaml"), encoding="utf-8")
    assert (
        main(
            ["sweep", str(sweep), "--scheduler", scheduler, "--out", str(tmp_path / "d"), "--quiet"]
        )
        == 0
    )
    assert (
        main(["sweep", str(sweep), "--workers", "0", "--out", str(tmp_path / "s"), "--quiet"]) == 0
    )
    out = capsys.readouterr().out
    assert "slopes: 8 runs, 0 failed" in out
    assert f"({scheduler})" in out
    dask, serial = _table(tmp_path / "d" / "runs.csv"), _table(tmp_path / "s" / "runs.csv")
    assert len(dask) == len(serial) == 8
    timing = {"wall_s", "realtime_factor"}
    for a, b in zip(dask, serial, strict=True):
        assert {k: v for k, v in a.items() if k not in timing} == {
            k: v for k, v in b.items() if k not in timing
        }
    # the runs really differ: slope and filter change the release
    assert len({row["release_drift_m"] for row in dask}) == 8
    assert {row["status"] for row in dask} == {"ok"}
    info = json.loads((tmp_path / "d" / "sweep.json").read_text())
    assert info["runs"] == 8
    assert info["scheduler"] == scheduler


def test_a_failed_run_on_the_cluster_is_a_row(scheduler: str, tmp_path: Path) -> None:
    good = Variant(0, str(SCENARIOS / "release.yaml"), (), (), 1, 0.5)
    bad = Variant(
        1, str(SCENARIOS / "release.yaml"), ("controller.translation.law=warp",), (), 1, 0.5
    )
    outcomes = run_variants([good, bad], scheduler=scheduler, progress=False)
    assert [o.status for o in outcomes] == ["ok", "failed"]
    assert "law: expected one of deadband_linear, isotropic, sigmoid" in outcomes[1].error


def test_a_local_cluster_keeps_its_own_periodic_work_rare() -> None:
    """The settings reach the worker process (through its nanny) and the scheduler, the worker
    samples no stacks, and this process's settings are its own again afterwards."""
    import dask.config
    import distributed  # noqa: F401  (Dask's defaults for these keys come with it)

    def settings() -> dict[str, object]:
        return {key: dask.config.get(key) for key in QUIET_CLUSTER}

    before = settings()
    assert before != QUIET_CLUSTER  # Dask's defaults, else the test shows nothing
    with RunPool(workers=1, progress=False) as pool:
        assert list(pool.client.run(settings).values()) == [QUIET_CLUSTER]
        assert pool.client.run_on_scheduler(settings) == QUIET_CLUSTER
        sampling = pool.client.run(lambda dask_worker: "profile" in dask_worker.periodic_callbacks)
        assert list(sampling.values()) == [False]
        pool.submit([Variant(0, str(SCENARIOS / "release.yaml"), (), (), 1, 0.2)])
        assert [o.status for o in pool.results()] == ["ok"]
    assert settings() == before


def test_an_unreachable_scheduler_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sweep = tmp_path / "slopes.yaml"
    sweep.write_text(SWEEP.format(scenario=SCENARIOS / "release.yaml"), encoding="utf-8")
    status = main(
        ["sweep", str(sweep), "--scheduler", "tcp://127.0.0.1:9", "--out", str(tmp_path / "x")]
    )
    err = capsys.readouterr().err.strip()
    assert status == 2
    assert err.startswith("hoh-cosim: --scheduler tcp://127.0.0.1:9: cannot reach a Dask scheduler")
    assert "\n" not in err
    assert not (tmp_path / "x").exists()


def test_tune_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    status = main(
        [
            "tune",
            "-n",
            "3",
            "--seeds",
            "1",
            "--workers",
            "0",
            "--scenarios",
            str(SCENARIOS),
            "--out",
            str(tmp_path / "t"),
            "--quiet",
        ]
    )
    out = capsys.readouterr().out
    assert status == 0, out
    assert "tune: 3 candidates" in out
    result = json.loads((tmp_path / "t" / "best.json").read_text())
    defaults = result["defaults"]
    # the defaults beat the seed on noise and lag, but their loop margin is under 6 dB
    assert defaults["attenuation_min"] > 3.0
    assert defaults["filter_lag_ms"] < 0.0
    assert defaults["gain_margin"] == pytest.approx(1.52, abs=0.01)
    rows = _table(tmp_path / "t" / "candidates.csv")
    assert len(rows) == 4
    for row in rows[1:]:
        # every sampled slope keeps the 6 dB margin by construction
        assert float(row["gain_margin"]) >= 2.0 - 1e-9
    if result["best"] is not None:
        assert result["best"]["feasible"] is True
        assert result["best"]["attenuation_min"] >= 2.0
