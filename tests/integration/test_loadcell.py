"""The load cell end to end: its driver on real pseudo-terminals, the contact scan it compensates,
and a rehearsed session with it (`hw rehearse --probe-sensor loadcell`).

The driver's tests play the Arduino on the master side of a raw pty pair (as the FSE103's tests do,
whose helpers they use); a baud mismatch is played by writing what a UART at 115200 baud reads from
a device at another rate (`hoh_cosim.rehearsal.serial_line`), since a pty has no baud rate.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.cli import main
from hoh_cosim.control.loadcell import SEED_CHAIN
from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.scenario import load_scenario
from hoh_cosim.hardware.loadcell import LoadCellPort, LoadCellSample, encode_line
from hoh_cosim.hardware.session_log import read_session
from hoh_cosim.rehearsal.serial_line import as_read_at
from tests.integration.test_fse103_port import open_pty, wait_for
from tests.integration.test_scenarios import SCENARIOS
from tests.xdist_groups import REAL_TIME

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs POSIX pseudo-terminals")
pytest.importorskip("serial")


def _lines(counts: list[int], t0_ms: int = 7000) -> bytes:
    return b"".join(encode_line(c, t0_ms + 5 * k) for k, c in enumerate(counts))


# --- the driver on a pty ----------------------------------------------------------------------


def test_good_lines_arrive_as_forces_along_the_axis_with_their_counts():
    with open_pty() as p:
        port = LoadCellPort(p.name, reconnect=False)
        with port:
            assert wait_for(lambda: port.connected)
            counts = [102, 250, 400, 1023]
            os.write(p.master, _lines(counts))
            assert wait_for(lambda: port.mailbox.latest()[1] == 4)
            sample, _n = port.mailbox.latest()
        assert isinstance(sample, LoadCellSample)
        assert (sample.count, sample.device_ms, port.latest_count) == (1023, 7015, 1023)
        np.testing.assert_array_equal(sample.values, [0.0, 0.0, -SEED_CHAIN.newtons(1023)])
        assert port.mailbox.stats.bad_frames == 0
        assert port.mailbox.error is None


def test_garbage_then_the_driver_resynchronises_at_the_next_line():
    with open_pty() as p:
        port = LoadCellPort(p.name, reconnect=False)
        with port:
            assert wait_for(lambda: port.connected)
            os.write(p.master, b"C,12,3\r\n" + _lines([300] * 5))
            os.write(p.master, bytes(range(128, 256)) + b"\r\n")  # a burst of noise on the line
            os.write(p.master, _lines([310] * 5, t0_ms=9000))
            assert wait_for(lambda: port.mailbox.latest()[1] == 10)
            sample, _ = port.mailbox.latest()
        assert (sample.count, sample.device_ms) == (310, 9020)
        assert port.mailbox.stats.bad_frames >= 2  # the partial line and the noise
        assert port.mailbox.error is None  # good lines came after it: nothing to say


def test_a_device_that_is_not_a_load_cell_is_named_in_one_line():
    with open_pty() as p:
        port = LoadCellPort(p.name, reconnect=False)
        with port:
            assert wait_for(lambda: port.connected)
            os.write(p.master, b"( 1.20 , -0.40 , 3.10 , 0.01 , 0.00 , 0.02 )\r\n" * 5)
            assert wait_for(lambda: port.mailbox.error is not None)
            error = port.mailbox.error
        assert port.mailbox.latest() == (None, 0)
        assert "\n" not in error
        assert error.startswith(f"load cell on {p.name}: expected lines 'LC,<ms>,<count>'")
        assert "'( 1.20 , -0.40 ," in error
        assert "not a load cell" in error


def test_a_baud_mismatch_is_named_in_one_line():
    with open_pty() as p:
        port = LoadCellPort(p.name, reconnect=False)  # 115200 baud, the device at 9600
        with port:
            assert wait_for(lambda: port.connected)
            os.write(p.master, as_read_at(_lines([300] * 40), sent_baud=9600, read_baud=115200))
            assert wait_for(lambda: port.mailbox.error is not None)
            error = port.mailbox.error
        assert port.mailbox.latest() == (None, 0)
        assert "\n" not in error
        assert error.startswith(f"load cell on {p.name}: expected lines")
        assert "at 115200 baud" in error
        assert "baud rate is another" in error


def test_a_missing_port_is_named_in_one_line(tmp_path: Path):
    missing = tmp_path / "ttyACM9"
    port = LoadCellPort(str(missing), reconnect=False)
    with port:
        assert wait_for(lambda: port.mailbox.error is not None)
    assert port.mailbox.error.startswith(f"ConnectionError: load cell on {missing}: cannot open:")
    assert "\n" not in port.mailbox.error


# --- the contact scan with the load cell --------------------------------------------------------


def test_the_load_cells_compensation_holds_the_contact_without_a_bounce():
    """contact_scan_loadcell over 20 s: the contact is held at about the hand's 8 N, no bounce, and
    the probe keeps its orientation (the friction across the axis taken from the wrist); without
    that, the friction's moment tilts the probe (what the cell cannot see)."""
    scenario = load_scenario(SCENARIOS / "contact_scan_loadcell.yaml", duration_s=20.0)
    signals = simulate(scenario, "inprocess", progress=False)
    F_contact = signals["plant.F_contact_B"]
    pressing = signals.time > 10.0  # well into the scan
    assert np.all(np.linalg.norm(F_contact[pressing], axis=1) > 2.0)  # never lost
    assert 6.5 < F_contact[pressing, 2].mean() < 9.5
    counts = signals["loadcell.count"][:, 0]
    assert counts[pressing].min() > SEED_CHAIN.counts(2.0)  # the cell felt the contact throughout
    R = signals["plant.R_BT"].reshape(-1, 3, 3)
    tilt = np.degrees(np.arccos(np.clip(-R[:, 2, 2], -1.0, 1.0)))
    assert tilt.max() < 10.0
    without = load_scenario(
        SCENARIOS / "contact_scan_loadcell.yaml",
        ["estimator.probe_correction.across_from_wrist_s=0"],
        duration_s=20.0,
    )
    R = simulate(without, "inprocess", progress=False)["plant.R_BT"].reshape(-1, 3, 3)
    assert np.degrees(np.arccos(np.clip(-R[:, 2, 2], -1.0, 1.0))).max() > 20.0


def test_the_two_engines_give_the_same_signals_with_the_load_cell():
    scenario = load_scenario(SCENARIOS / "contact_scan_loadcell.yaml", duration_s=9.0)
    fmu = simulate(scenario, "fmu", progress=False)
    inprocess = simulate(scenario, "inprocess", progress=False)
    assert fmu.columns == inprocess.columns
    assert np.max(np.abs(fmu.values - inprocess.values)) <= 1e-9
    assert np.ptp(fmu["loadcell.count"]) > 50  # the cell was pressed


# --- a rehearsed session ---------------------------------------------------------------------


@REAL_TIME
def test_hw_rehearse_with_the_load_cell_runs_a_clean_session(tmp_path, capsys):
    log = tmp_path / "r.mcap"
    status = main(
        [
            *("hw", "rehearse", "--probe-sensor", "loadcell", "--task", "scan"),
            *("--seconds", "6", "--rebias-samples", "200", "--log", str(log)),
        ]
    )
    out = capsys.readouterr().out
    assert status == 0, out
    assert "session ended: 6 s done" in out
    assert "FSE103" not in out
    rebias = next(line for line in out.splitlines() if line.startswith("rebias done"))
    assert "probe offset [0.0, 0.0, -" in rebias
    assert ", 200.0 Hz; off the" in rebias
    session = read_session(log)
    assert session.complete
    assert "robot: guiding in contact" in out  # the scan's press reached the phantom


@REAL_TIME
def test_an_fse103_where_the_rig_says_load_cell_ends_the_start_in_one_line(tmp_path):
    """The runner given a load cell's driver on the FSE103's port: no session, one line naming the
    port, the expected lines and what came instead, and the robot never commanded to move."""
    from hoh_cosim.hardware.ft150 import FT150Stream
    from hoh_cosim.hardware.runner import Runner
    from hoh_cosim.rehearsal.rehearse import rehearsal_config, truth_calibration
    from hoh_cosim.rehearsal.world import RehearsalWorld, WorldSetup

    with RehearsalWorld(WorldSetup(task_start_s=None, watchdog_hz=5.0)) as world:
        config = rehearsal_config(world, tmp_path, rebias_samples=100)
        ft = FT150Stream("127.0.0.1", world.ft_port)
        probe = LoadCellPort(world.pty_name, reconnect=False)
        robot = world.robot()
        result = Runner(config, robot, ft, probe, truth_calibration(world.truth)).run(5.0)
        assert world.last_commanded() != world.last_commanded()  # NaN: never asked to move
    assert not result.clean
    assert result.rebias is None
    assert "\n" not in result.cause
    assert result.cause.startswith(f"load cell on {world.pty_name}: no data within 5 s (")
    assert "expected lines 'LC,<ms>,<count>' at 115200 baud, got bytes that are not text" in (
        result.cause
    )
