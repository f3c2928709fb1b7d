"""What a user meets when things go wrong on the command line: one line naming the cause, a status
that says so, and nothing half-written. Also the results files a run writes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from hoh_cosim.cli import main

ROOT = Path(__file__).resolve().parents[2]
CIRCLES = ROOT / "scenarios" / "circles.yaml"


def _hoh(*args: str) -> list[str]:
    return [sys.executable, "-m", "hoh_cosim", *args]


def _no_staging(directory: Path) -> list[Path]:
    return [p for p in directory.iterdir() if p.name.startswith(".")]


@pytest.mark.parametrize("engine", ["inprocess", "fmu"])
def test_ctrl_c_stops_a_run_with_status_130_and_writes_nothing(tmp_path, engine):
    out = tmp_path / "run"
    process = subprocess.Popen(
        _hoh(str(CIRCLES), "--duration", "600", "--engine", engine, "--out", str(out), "--quiet"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        # a child of a non-interactive shell may inherit SIGINT ignored: give it Python's default
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    # interrupt once the master is stepping (the progress line needs a terminal; wait for the
    # FMUs or blocks to be up: the first second of a 600 s run)
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.2)
        if _stepping(process.pid):
            break
    time.sleep(1.0)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert err.strip().splitlines() == ["hoh-cosim: interrupted"]
    assert not out.exists()
    assert not _no_staging(tmp_path)


def _stepping(pid: int) -> bool:
    """The process has been busy for a while (CPU time above 2 s): past the imports and builds."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return False
    ticks = os.sysconf("SC_CLK_TCK")
    return (int(fields[11]) + int(fields[12])) / ticks > 2.0


def test_an_output_under_a_file_is_refused_before_the_run(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    status = main([str(CIRCLES), "--out", str(blocker / "run"), "--engine", "inprocess"])
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith(f"hoh-cosim: --out {blocker / 'run'}: cannot write in {blocker}: ")
    assert len(err.strip().splitlines()) == 1
    assert "simulated" not in capsys.readouterr().out


def test_an_immutable_output_directory_is_refused_before_the_run(tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    if subprocess.run(["chattr", "+i", str(locked)], capture_output=True).returncode != 0:
        pytest.skip("chattr +i is not possible here")
    try:
        status = main([str(CIRCLES), "--out", str(locked / "run"), "--engine", "inprocess"])
        err = capsys.readouterr().err
    finally:
        subprocess.run(["chattr", "-i", str(locked)], check=True)
    assert status == 2
    assert err.strip() == (
        f"hoh-cosim: --out {locked / 'run'}: cannot write in {locked}: Operation not permitted"
    )


def test_a_rehearsal_log_that_cannot_be_written_is_refused_before_the_world_starts(
    tmp_path, capsys
):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    status = main(["hw", "rehearse", "--seconds", "1", "--log", str(blocker / "s.mcap")])
    captured = capsys.readouterr()
    assert status == 2
    assert captured.err.startswith(f"hoh-cosim: --log: cannot write in {blocker}: ")
    assert "starting the rehearsal world" not in captured.out


def test_hw_sensors_fails_at_once_naming_a_refused_stream(capsys):
    started = time.monotonic()
    status = main(["hw", "sensors", "--ft", "127.0.0.1:1", "--seconds", "30"])
    captured = capsys.readouterr()
    assert status == 1
    first = captured.err.splitlines()[0]
    assert first.startswith("hoh-cosim: FT-150 stream at 127.0.0.1:1: no data (")
    assert "Connection refused" in first
    # it does not wait out the 30 s once every stream has failed
    assert time.monotonic() - started < 25.0


def test_hw_sensors_fails_naming_a_missing_probe_device(tmp_path, capsys):
    device = tmp_path / "ttyNONE"
    status = main(["hw", "sensors", "--probe", str(device), "--seconds", "30", "--json"])
    captured = capsys.readouterr()
    assert status == 1
    assert captured.err.splitlines()[0].startswith(f"hoh-cosim: FSE103 on {device}: no data (")
    figures = json.loads(captured.out)
    assert figures["probe"]["frames"] == 0
    assert "No such file or directory" in figures["probe"]["error"]


def test_results_as_parquet_and_as_csv_hold_the_same_columns(tmp_path):
    args = [str(CIRCLES), "--engine", "inprocess", "--duration", "4", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "p")]) == 0
    assert main(["run", *args, "--out", str(tmp_path / "c"), "--format", "csv"]) == 0
    assert not (tmp_path / "p" / "signals.csv").exists()
    assert not (tmp_path / "c" / "signals.parquet").exists()
    table = pq.read_table(tmp_path / "p" / "signals.parquet")
    with (tmp_path / "c" / "signals.csv").open(encoding="utf-8") as f:
        header = f.readline().strip().split(",")
        rows = [line.strip().split(",") for line in f]
    assert table.column_names == header
    assert header[-2:] == ["controller.status", "controller.status_text"]
    numeric = np.array([[float(x) for x in row[:-1]] for row in rows])
    for i, name in enumerate(header[:-1]):
        np.testing.assert_allclose(table[name].to_numpy(), numeric[:, i], rtol=1e-9, atol=1e-12)
    text = [row[-1] for row in rows]
    assert table["controller.status_text"].to_pylist() == text
    # the rebias holds the controller (NOT_READY), then it runs clean
    assert "NOT_READY" in text
    assert text[-1] == "ok"
    codes = table["controller.status"].to_numpy()
    assert set(np.unique(codes[np.array(text) == "NOT_READY"])) == {4096.0}


def test_the_summary_says_each_thing_once(tmp_path):
    out = tmp_path / "run"
    assert main([str(CIRCLES), "--engine", "inprocess", "--duration", "2", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert "wall_s" not in summary
    assert "realtime_factor" not in summary
    assert summary["metrics"]["wall_s"] > 0
    assert summary["metrics"]["realtime_factor"] > 0


@pytest.mark.parametrize("where", ["hw rehearse", "hw run"])
def test_a_session_log_that_exists_is_refused_before_anything_runs(tmp_path, where):
    log = tmp_path / "session.mcap"
    log.write_bytes(b"an earlier session")
    if where == "hw rehearse":
        argv = ["hw", "rehearse", "--seconds", "2", "--log", str(log)]
    else:
        rig = tmp_path / "rig.yaml"
        rig.write_text(
            "robot:\n  host: 127.0.0.1\nprobe: null\ncalibration: calibration.json\n",
            encoding="utf-8",
        )
        argv = ["hw", "run", str(rig), "--log", str(log)]
    done = subprocess.run(_hoh(*argv), capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        f"hoh-cosim: --log: {log} exists; a session log is never overwritten"
    ]
    assert "starting" not in done.stdout  # nothing ran
    assert log.read_bytes() == b"an earlier session"
