"""The load cell: its chain's transfer, the sensor model and its faults, the line parser, and
`probe_sensor` in a scenario."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hoh_cosim.control.frames import R_BL_EQ3
from hoh_cosim.control.loadcell import (
    ADC_COUNTS,
    COUNTS_PER_N,
    FULL_SCALE_COUNT,
    R_SL_SEED,
    SEED_CHAIN,
    ZERO_COUNT,
    LoadCellChain,
    force_L,
)
from hoh_cosim.cosim.scenario import load_scenario
from hoh_cosim.errors import ConfigError
from hoh_cosim.hardware.loadcell import (
    LOCK_LINES,
    MAX_LINE_BYTES,
    LoadCellLine,
    LoadCellParser,
    encode_line,
)
from hoh_cosim.rehearsal.serial_line import as_read_at
from plant_models.loadcell import (
    OPEN_CIRCUIT_COUNT,
    SATURATED_COUNT,
    SATURATED_TENSION_V,
    LoadCellParams,
    LoadCellSensor,
)

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
RATE_HZ = LoadCellParams().rate_hz


# --- the chain --------------------------------------------------------------------------------


def test_the_chain_gives_the_seeds_volt_per_count_and_a_usable_span():
    assert 1.0 / SEED_CHAIN.counts_per_V == pytest.approx(0.0049, abs=1e-4)  # seed 3.B.2
    assert 14.0 < COUNTS_PER_N < 17.0  # about 0.064 N a count
    assert 90 < ZERO_COUNT < 115  # the zero above the bottom rail: a tension stays visible
    assert ZERO_COUNT < FULL_SCALE_COUNT < ADC_COUNTS - 1  # full scale below the top rail


@pytest.mark.parametrize("compression_N", [0.0, 0.5, 3.0, 8.0, 20.0, 44.0])
def test_counts_and_newtons_invert_each_other_within_half_a_count(compression_N):
    count = SEED_CHAIN.counts(compression_N)
    assert abs(SEED_CHAIN.newtons(count) - compression_N) <= 0.5 / COUNTS_PER_N + 1e-12
    assert SEED_CHAIN.counts(SEED_CHAIN.newtons(count)) == count


def test_the_adc_clips_at_its_rails():
    assert SEED_CHAIN.count(-1.0) == 0
    assert SEED_CHAIN.count(7.0) == ADC_COUNTS - 1
    assert SEED_CHAIN.counts(1000.0) == ADC_COUNTS - 1


def test_the_chain_refuses_a_gain_of_zero():
    with pytest.raises(ConfigError, match=r"gain must be > 0.0, got 0.0"):
        LoadCellChain(gain=0.0)


def test_eq3_mounting_puts_the_cells_axis_along_the_probe():
    # at home the wrist sensor is eq. 1 and the probe points down: z_L is -z_B, handle to tip
    assert np.allclose(R_BL_EQ3[:, 2], [0.0, 0.0, -1.0])
    assert np.allclose(R_SL_SEED[:, 2], [0.0, 0.0, -1.0])  # the tool hangs along -z_S
    assert np.allclose(force_L(5.0), [0.0, 0.0, -5.0])  # a compression pushes back up the probe


# --- the sensor model -------------------------------------------------------------------------


def _readings(params: LoadCellParams, force_L_N, seconds: float = 1.0, seed: int = 3):
    """Every delivered reading's (count, force_P) over `seconds` of 1 ms steps under a constant
    true force in L."""
    sensor = LoadCellSensor(params, rng=np.random.default_rng(seed))
    true = {"force_P_true": np.asarray(force_L_N, dtype=float)}
    counts, forces, seen = [], [], 0.0
    for k in range(round(seconds / 1e-3)):
        out = sensor.step(k * 1e-3, 1e-3, true)
        if out["counter"][0] != seen:
            seen = out["counter"][0]
            counts.append(out["count"][0])
            forces.append(out["force_P"].copy())
    return np.array(counts), np.array(forces)


def test_a_reading_is_a_whole_count_and_its_force_the_counts():
    counts, forces = _readings(LoadCellParams(), [0.0, 0.0, -8.0])
    assert len(counts) == pytest.approx(RATE_HZ, abs=1)
    assert np.all(counts == np.round(counts))
    assert np.all(forces[:, :2] == 0.0)  # one axis: nothing across it
    expected = [-SEED_CHAIN.newtons(c) for c in counts]
    np.testing.assert_allclose(forces[:, 2], expected, rtol=0, atol=1e-12)
    # 8 N of compression, the zero's imbalance and the chain's half count on top
    assert 7.8 < -forces[:, 2].mean() - LoadCellParams().offset_V / SEED_CHAIN.volts_per_N < 8.3


def test_the_noise_is_about_half_a_count_and_seeded():
    counts, _ = _readings(LoadCellParams(), [0.0, 0.0, -5.0], seconds=2.0)
    assert 0.2 < counts.std() < 0.9
    again, _ = _readings(LoadCellParams(), [0.0, 0.0, -5.0], seconds=2.0)
    np.testing.assert_array_equal(counts, again)
    other, _ = _readings(LoadCellParams(), [0.0, 0.0, -5.0], seconds=2.0, seed=4)
    assert not np.array_equal(counts, other)


def test_compression_only_a_pull_and_a_side_load_read_as_no_load():
    ideal = LoadCellParams(ideal=True)
    rest, _ = _readings(ideal, [0.0, 0.0, 0.0], seconds=0.1)
    pulled, _ = _readings(ideal, [0.0, 0.0, 12.0], seconds=0.1)
    sideways, _ = _readings(ideal, [9.0, -7.0, 0.0], seconds=0.1)
    pressed, _ = _readings(ideal, [0.0, 0.0, -12.0], seconds=0.1)
    assert np.all(pulled == rest[0])
    assert np.all(sideways == rest[0])
    assert np.all(pressed - rest[0] == pytest.approx(12.0 * COUNTS_PER_N, abs=1.0))


def test_the_seeds_saturated_cell_moves_a_count_when_pressed_and_half_a_volt_when_pulled():
    saturated = LoadCellParams(saturated=True)
    rest, _ = _readings(saturated, [0.0, 0.0, 0.0], seconds=2.0)
    pressed, _ = _readings(saturated, [0.0, 0.0, -20.0], seconds=2.0)
    pulled, _ = _readings(saturated, [0.0, 0.0, 20.0], seconds=2.0)
    assert abs(rest.mean() - SATURATED_COUNT) < 1.0  # near the top rail
    assert 0.4 < pressed.mean() - rest.mean() < 1.6  # about one bit (+5 mV), seed Fig. 9
    volts = (rest.mean() - pulled.mean()) / SEED_CHAIN.counts_per_V
    assert 0.8 * SATURATED_TENSION_V < volts < 1.1 * SATURATED_TENSION_V  # about -0.5 V


def test_an_open_circuit_reads_the_rail_still_and_deaf_to_the_load():
    for force in ([0.0, 0.0, 0.0], [0.0, 0.0, -30.0], [0.0, 0.0, 10.0]):
        counts, _ = _readings(LoadCellParams(open_circuit=True), force, seconds=0.2)
        assert np.all(counts == OPEN_CIRCUIT_COUNT)


def test_a_drifting_zero_creeps_at_its_rate():
    rate = 6.0  # [N/min]: 1 N in 10 s
    counts, forces = _readings(LoadCellParams(zero_drift_N_per_min=rate), [0, 0, -4.0], 10.0)
    n = len(counts) // 10  # the first and the last second
    moved = -forces[-n:, 2].mean() - -forces[:n, 2].mean()
    assert moved == pytest.approx(rate / 60.0 * 9.0, abs=0.15)


def test_a_dropout_delivers_no_reading():
    counts, _ = _readings(LoadCellParams(connected=False), [0, 0, -4.0], seconds=0.5)
    assert len(counts) == 0


# --- the line parser --------------------------------------------------------------------------


def _lines(n: int, t0_ms: int = 1000) -> bytes:
    return b"".join(encode_line(300 + k, t0_ms + 5 * k) for k in range(n))


def test_lines_whatever_the_chunking():
    stream = _lines(20)
    whole = LoadCellParser().feed(stream)
    parser = LoadCellParser()
    bytewise = [line for b in stream for line in parser.feed(bytes([b]))]
    assert whole == bytewise == [LoadCellLine(300 + k, 1000 + 5 * k) for k in range(20)]
    assert parser.bad_lines == 0
    assert parser.pending_bytes == 0


def test_garbage_then_the_parser_is_back_in_step_at_the_next_line():
    parser = LoadCellParser()
    mid_line = b"2,317\r\n"  # listening began inside a line
    junk = bytes(range(1, 9)) + b"\xff\xfe no line end here " * 4 + b"\n"
    lines = parser.feed(mid_line + _lines(3) + junk + _lines(3, t0_ms=5000))
    assert [line.device_ms for line in lines] == [1000, 1005, 1010, 5000, 5005, 5010]
    assert parser.bad_lines >= 3  # the partial line, the junk cut every MAX_LINE_BYTES, its tail
    assert parser.bad_run == 0
    assert parser.diagnosis("/dev/x", 115200) is None


def test_endless_garbage_keeps_the_memory_bounded():
    parser = LoadCellParser()
    for _ in range(200):
        assert parser.feed(b"\x80" * 97) == []
        assert parser.pending_bytes <= MAX_LINE_BYTES
    assert parser.bad_lines >= 200 * 97 // MAX_LINE_BYTES - 1


@pytest.mark.parametrize(
    "line",
    [b"LC,12,1024\r\n", b"LC,4294967296,5\r\n", b"LC,12\r\n", b"lc,12,5\r\n", b"LC,12,5,7\r\n"],
)
def test_a_line_out_of_range_or_shape_is_bad(line):
    parser = LoadCellParser()
    assert parser.feed(line) == []
    assert parser.bad_lines == 1


def test_the_milliseconds_wrap_and_a_bare_newline_is_a_line_end():
    lines = LoadCellParser().feed(b"LC,4294967295,7\nLC,4,8\r\n")
    assert lines == [LoadCellLine(7, 2**32 - 1), LoadCellLine(8, 4)]
    assert encode_line(2000, 2**32 + 3) == b"LC,3,1023\r\n"


def test_a_device_speaking_another_line_format_is_named_in_one_line():
    parser = LoadCellParser()
    parser.feed(b"( 1.20 , -0.40 , 3.10 , 0.01 , 0.00 , 0.02 )\r\n" * LOCK_LINES)
    message = parser.diagnosis("/dev/ttyACM0", 115200)
    assert message is not None
    assert "\n" not in message
    assert message.startswith("load cell on /dev/ttyACM0: expected lines 'LC,<ms>,<count>'")
    assert "at 115200 baud" in message
    assert "'( 1.20 , -0.40 ," in message
    assert "not a load cell (its line format is another)" in message


@pytest.mark.parametrize("device_baud", [9600, 57600, 230400])
def test_lines_read_at_the_wrong_baud_rate_are_named_as_such(device_baud):
    parser = LoadCellParser()
    assert parser.feed(as_read_at(_lines(40), sent_baud=device_baud, read_baud=115200)) == []
    message = parser.diagnosis("/dev/ttyACM0", 115200)
    assert message is not None
    assert "\n" not in message
    assert "got bytes that are not text" in message
    assert "baud rate is another" in message


def test_lines_read_at_the_right_baud_rate_pass_the_uart_emulation_unchanged():
    stream = _lines(10)
    assert as_read_at(stream, sent_baud=115200, read_baud=115200) == stream


# --- probe_sensor in a scenario ---------------------------------------------------------------


def test_probe_sensor_loadcell_swaps_the_fse103_for_the_load_cell_in_place():
    fse = load_scenario(SCENARIOS / "contact_scan.yaml")
    cell = load_scenario(SCENARIOS / "contact_scan_loadcell.yaml")
    assert list(cell.components) == ["loadcell" if n == "fse103" else n for n in fse.components]
    assert cell.components["loadcell"].kind.name == "loadcell"
    np.testing.assert_array_equal(cell.components["plant"].params.tool.R_SP, R_SL_SEED)
    estimator = cell.components["estimator"].params
    np.testing.assert_array_equal(estimator.R_SP, R_SL_SEED)
    assert estimator.probe_packet_period_s == pytest.approx(1.0 / RATE_HZ)
    assert estimator.probe_correction.across_from_wrist_s > 0.0
    assert cell.components["controller"].params.probe_period_s == pytest.approx(1.0 / RATE_HZ)
    ends = {c.src for c in cell.connections} | {c.dst for c in cell.connections}
    assert "fse103" not in ends
    assert "loadcell" in ends


def test_probe_sensor_none_runs_without_a_probe_sensor(tmp_path):
    path = tmp_path / "none.yaml"
    path.write_text(f"extends: {SCENARIOS / 'contact_scan.yaml'}\nprobe_sensor: none\n")
    scenario = load_scenario(path)
    assert "fse103" not in scenario.components
    assert scenario.components["estimator"].params.use_probe is False
    assert scenario.components["controller"].params.use_probe is False


def test_an_unknown_probe_sensor_is_named_with_the_choices(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(f"extends: {SCENARIOS / 'contact_scan.yaml'}\nprobe_sensor: honeywell\n")
    with pytest.raises(
        ConfigError,
        match=r"bad\.yaml: probe_sensor: expected one of fse103, loadcell, none, got 'honeywell'",
    ):
        load_scenario(path)


@settings(max_examples=200, deadline=None)
@given(
    garbage=st.lists(
        st.binary(max_size=150).map(lambda b: b"\xff" + b.replace(b"\n", b"")), max_size=6
    ),
    cuts=st.lists(st.integers(min_value=1, max_value=40), max_size=30),
)
def test_the_lines_come_back_whatever_the_garbage_between_them_and_the_chunking(garbage, cuts):
    """Garbage (no line end in it, so its own line is bad) ended by a line end between good lines,
    cut anywhere: every good line comes back in order, and the parser never holds more than a
    line's worth."""
    good = [encode_line(100 + k, 10 * k) for k in range(len(garbage) + 1)]
    stream = good[0] + b"".join(g + b"\n" + line for g, line in zip(garbage, good[1:], strict=True))
    parser, lines, at = LoadCellParser(), [], 0
    for n in [*cuts, len(stream)]:
        lines += parser.feed(stream[at : at + n])
        at += n
        assert parser.pending_bytes <= MAX_LINE_BYTES
    assert lines == [LoadCellLine(100 + k, 10 * k) for k in range(len(good))]
    assert parser.bad_lines >= len(garbage)


def test_a_text_line_with_a_stray_byte_is_shown_escaped():
    parser = LoadCellParser()
    parser.feed(b"F 1.0 2.0 3.0 \xb0C\r\n" * LOCK_LINES)
    assert "got 'F 1.0 2.0 3.0 \\\\xb0C'" in parser.diagnosis("/dev/x", 115200)
