"""`hw check`'s measurements and verdicts on recorded samples, without real time: a healthy rig passes
with a margin, each planted kind of fault fails with its cause named, the session is refused on a
failing sensor unless overridden by name, and the report has its keys."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.estimator import (
    FSE103_NOISE_MAX,
    FT150_NOISE_MAX_S,
    FT150_TORQUE_NOISE_MAX_S,
    NOISE_MAX_PER_SIGMA,
)
from hoh_cosim.control.frames import R_BS_EQ1, R_SP_SEED, rotvec_to_matrix
from hoh_cosim.control.gravity import SEED_TOOL, tool_weight_wrench_S
from hoh_cosim.control.sequencer import SequencerParams, tilted_orientations
from hoh_cosim.errors import ConfigError
from hoh_cosim.hardware.check import (
    MAP_RESIDUAL_N,
    CheckRecord,
    Claims,
    LoadCellSpec,
    ProbeEvidence,
    Stream,
    Window,
    check_loadcell,
    frame_fit,
    judge,
    map_residual_N,
    push_pairs,
    rate_figures,
    report,
    session_refusal,
)
from hoh_cosim.rehearsal.planted import PLANTED, Planted, planted_world
from plant_models.sensors import FSE103Params, FSE103Sensor, HousingParams

SIGMA_FT = np.concatenate([FT150_NOISE_MAX_S, FT150_TORQUE_NOISE_MAX_S]) / NOISE_MAX_PER_SIGMA
SIGMA_P = FSE103_NOISE_MAX / NOISE_MAX_PER_SIGMA
BIAS = np.array([1.8, -2.4, 3.1, 0.041, -0.027, 0.013])
CLAIMS = Claims(ft_rate_hz=200.0, probe_rate_hz=50.0, R_SP=R_SP_SEED, tool=SEED_TOOL)
QUARTER_TURN = rotvec_to_matrix([0.5 * math.pi, 0.0, 0.0])  # about P's x, the probe's axis


def _pushes_S(t: np.ndarray, start_s: float, directions_S: np.ndarray, peaks: list[float]):
    """Raised-cosine pushes of 2 s each from start_s + 0.5 s, as the emulated hand's."""
    tau = t - start_s - 0.5
    k = np.floor(tau / 2.0).astype(int)
    phase = tau / 2.0 - k
    out = np.zeros((t.size, 3))
    for i, (d, peak) in enumerate(zip(directions_S, peaks, strict=True)):
        on = k == i
        out[on] = (peak * 0.5 * (1.0 - np.cos(2.0 * np.pi * phase[on])))[:, None] * d
    return out


def record(
    seed: int = 1,
    *,
    ft_rate_hz: float = 200.0,
    ft_signs=(1.0,) * 6,
    ft_dead: int | None = None,
    probe_rotation: np.ndarray | None = None,
    housing: HousingParams | None = None,
) -> CheckRecord:
    """A check as `check_run.record_check` records it, from the models: the tool's weight at the
    seed's home and three 45° tilts, three pushes on the tip, the sensors' noise."""
    rng = np.random.default_rng(seed)
    poses = tilted_orientations(
        R_BS_EQ1, SequencerParams(tilts=1, tilt_min_deg=45, tilt_max_deg=45, directions=3)
    )
    plan = [("rest", 0.0, 1.0, R_BS_EQ1)]
    plan += [("pose", 2.0 + 1.5 * i, 2.5 + 1.5 * i, R) for i, R in enumerate(poses)]
    plan += [("rest", 7.0, 8.0, R_BS_EQ1), ("pushes", 8.0, 15.0, R_BS_EQ1)]
    windows = tuple(Window(kind, a, b, R) for kind, a, b, R in plan)
    axis_S = np.array(
        [0.0, 0.0, 1.0]
    )  # the tip pushed up its axis (+z_S = +z_B at home), within 60°
    directions = []
    for _ in range(3):
        tilt, azimuth = np.radians(rng.uniform(10, 50)), rng.uniform(0, 2 * np.pi)
        d = np.array([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), 0.0])
        directions.append(d + np.cos(tilt) * axis_S)
    peaks = list(rng.uniform(6.0, 15.0, 3))

    def truth_S(t: np.ndarray) -> np.ndarray:
        w = np.zeros((t.size, 6))
        for _kind, a, b, R in plan:
            inside = (t >= a - 0.5) & (t <= b)
            w[inside] = tool_weight_wrench_S(R, SEED_TOOL)
        w[:, :3] += _pushes_S(t, 8.0, np.array(directions), peaks)
        return w

    t_ft = np.arange(0.0, 15.0, 1.0 / ft_rate_hz)
    ft = truth_S(t_ft) + BIAS + rng.standard_normal((t_ft.size, 6)) * SIGMA_FT
    ft = np.round(ft * np.asarray(ft_signs) / 5e-4) * 5e-4
    if ft_dead is not None:
        ft[:, ft_dead] = 0.0
    t_p = np.arange(0.0, 15.0, 0.02)
    sensor = FSE103Sensor(FSE103Params(housing=housing or HousingParams()), rng=rng)
    # the probe sensor carries the pushes on the tip only: R_SPᵀ f_S, row by row
    f_P = _pushes_S(t_p, 8.0, np.array(directions), peaks) @ R_SP_SEED
    turn = np.eye(3) if probe_rotation is None else probe_rotation
    m_P = np.array([sensor.housing_output(turn @ f) for f in f_P])
    m_P += np.array([0.3, -0.2, 0.5]) + rng.standard_normal(m_P.shape) * SIGMA_P
    return CheckRecord(Stream(t_ft, ft), Stream(t_p, m_P), windows)


def _failed(verdict) -> dict[str, str]:
    return {f.what: f.text for f in verdict.findings if f.judged and not f.ok}


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_a_healthy_rig_passes_with_its_advice(seed):
    ft, probe = judge(record(seed), CLAIMS, "fse103")
    assert ft.ok, ft.line()
    assert probe.ok, probe.line()
    assert ft.line().startswith("FT-150: ok (rate 200.0 Hz")
    # the seed's housing redirects force: the check says the probe check is needed
    assert "probe check" in probe.line()


def test_a_flipped_wrist_axis_is_named_and_the_probe_not_judged_against_it():
    ft, probe = judge(record(ft_signs=(-1.0,) + (1.0,) * 5), CLAIMS, "fse103")
    assert "Fx sign flipped: gain -" in _failed(ft)["axis signs"]
    assert probe.ok
    assert "pushes not judged: the FT-150, their reference, failed" in probe.line()


def test_a_dead_wrist_channel_is_flat_and_does_not_respond():
    (ft,) = judge(record(ft_dead=1), CLAIMS, "none")
    failed = _failed(ft)
    assert "Fy flat: σ 0 N at rest" in failed["noise"]
    assert "Fy does not respond: gain +0.00" in failed["axis signs"]


def test_a_wrist_at_a_quarter_of_its_claimed_rate():
    (ft,) = judge(record(ft_rate_hz=50.0), CLAIMS, "none")
    assert _failed(ft)["rate"].startswith("rate 50.0 Hz against 200 Hz ±20 %")
    assert ft.line().startswith("FT-150: FAIL rate 50.0 Hz")


def test_a_probe_sensor_turned_a_quarter_turn_about_its_axis():
    _, probe = judge(record(probe_rotation=QUARTER_TURN), CLAIMS, "fse103")
    text = _failed(probe)["frame"]
    angle = float(text.split(" by ")[1].split("°")[0])
    assert angle > 60.0, text


def test_a_probe_sensor_with_an_axis_flipped_is_a_reflection():
    # seed 2's pushes span space (their third singular value a quarter of the first): pushes in a
    # plane show a flip across it as a turn, or not at all (frame_fit)
    _, probe = judge(record(2, probe_rotation=np.diag([1.0, -1.0, 1.0])), CLAIMS, "fse103")
    assert "axis sign flipped: a reflection fits with " in _failed(probe)["frame"]


def test_a_housing_beyond_the_online_map_recommends_the_probe_check():
    housing = PLANTED["fse103_nonlinear_housing"].planted["housing"]
    _, probe = judge(record(housing=housing), CLAIMS, "fse103")
    text = _failed(probe)["linearity"]
    assert "beyond what the online map corrects; run the probe check" in text
    residual = float(text.split("leaves ")[1].split(" N")[0])
    assert residual > 1.5 * MAP_RESIDUAL_N
    assert set(_failed(probe)) == {"linearity"}  # no frame judged on a reading no map fits


def test_the_map_residual_is_zero_for_a_reading_the_map_describes():
    rng = np.random.default_rng(5)
    m = rng.normal(0.0, 5.0, (200, 3))
    f = m @ np.array([[1.1, 0.2, 0.0], [0.0, 0.9, 0.1], [0.05, 0.0, 1.0]]) + 0.02 * m * np.abs(m)
    assert map_residual_N(f, m) < 1e-9
    assert map_residual_N(f, m, linear_only=True) > 0.1


def test_frame_fit_finds_a_rotation_and_its_angle():
    rng = np.random.default_rng(6)
    f = rng.normal(0.0, 5.0, (100, 3))
    R = rotvec_to_matrix([0.0, 0.0, np.radians(30.0)])
    fit = frame_fit(f, f @ R.T)
    assert fit["angle_deg"] == pytest.approx(30.0, abs=1e-6)
    assert not fit["reflected"]
    assert fit["scale"] == pytest.approx(1.0)


def test_rate_figures_count_the_late_gaps():
    t = np.concatenate([np.arange(0.0, 1.0, 0.005), 1.1 + np.arange(0.0, 1.0, 0.005)])
    r = rate_figures(t, 200.0)
    assert r["longest_gap_s"] == pytest.approx(0.105, abs=1e-9)
    assert 0.0 < r["late"] < 0.01
    assert rate_figures(np.array([1.0]), 200.0)["rate_hz"] == 0.0


def test_a_failing_sensor_refuses_the_session_unless_overridden_by_name():
    verdicts = judge(record(ft_dead=1), CLAIMS, "fse103")
    assert session_refusal(verdicts, []) == ["ft150"]
    assert session_refusal(verdicts, ["ft150"]) == []
    with pytest.raises(ConfigError, match=r"--override: expected one of ft150, fse103, got 'ati'"):
        session_refusal(verdicts, ["ati"])


def test_the_report_has_its_keys():
    verdicts = judge(record(ft_dead=1), CLAIMS, "fse103")
    out = report(verdicts, ["ft150"], {"kind": "rehearsal", "seed": 1})
    assert set(out) == {
        "kind",
        "seed",
        "ok",
        "sensors",
        "overrides",
        "session",
        "refused_by",
    }
    assert out["session"] == "allowed"
    assert not out["ok"]
    ft = out["sensors"]["ft150"]
    assert set(ft) == {"ok", "line", "advice", "findings"}
    assert set(ft["findings"]) == {
        "rate",
        "regularity",
        "noise",
        "drift",
        "axis signs",
        "frame",
        "linearity",
        "range",
    }
    assert set(ft["findings"]["noise"]) == {"ok", "judged", "text", "value", "limit"}


def test_an_unknown_probe_sensor_is_refused():
    with pytest.raises(
        ConfigError, match=r"--probe-sensor: expected one of fse103, loadcell, none, got 'ati'"
    ):
        judge(record(), CLAIMS, "ati")


def test_planted_faults_reach_the_world_and_refuse_what_a_probe_cannot_show():
    planted, changes = planted_world(["ft_sign_flipped", "ft_dead_channel", "ft_rate_low"], "none")
    assert changes == {"ft_rate_hz": 50.0}
    values = planted.ft_values(np.arange(1.0, 7.0))
    assert values.tolist() == [-1.0, 0.0, 3.0, 4.0, 5.0, 6.0]
    assert Planted().ft_values(np.ones(6)).tolist() == [1.0] * 6
    with pytest.raises(ConfigError, match=r"--fault: expected one of ft_sign_flipped, .*got 'x'"):
        planted_world(["x"], "fse103")
    with pytest.raises(
        ConfigError, match=r"--fault probe_frame_rotated: needs --probe-sensor fse103, got none"
    ):
        planted_world(["probe_frame_rotated"], "none")
    planted, _ = planted_world(["probe_frame_rotated"], "fse103")
    assert planted.probe_force(np.array([1.0, 2.0, 0.0])) == pytest.approx([1.0, 0.0, 2.0])


# --- the load cell's entry, on samples as its driver would deliver them ------------------------
COUNTS_PER_N = 20.0  # an illustrative gain for the test: 10-bit ADC, ~50 N span
LOADCELL = LoadCellSpec(counts_of=lambda newtons: 100.0 + COUNTS_PER_N * np.asarray(newtons))


def loadcell_record(saturated: bool, seed: int = 1) -> CheckRecord:
    """The FSE103's record with a load cell in its place: counts 100 + 20/N along its z (the
    probe's axis, compression positive), quantised to whole counts; saturated: pinned at the ADC's
    top with a count's flicker, as the seed's (Fig. 9)."""
    base = record(seed, housing=HousingParams(redirection=0, gain_error=0, stiffening=0))
    probe = base.probe
    assert probe is not None
    push = base.probe.values - np.array([0.3, -0.2, 0.5])  # the housing passes the push whole
    counts = np.round(100.0 + COUNTS_PER_N * np.maximum(push[:, 0], 0.0))  # the probe's axis: x_P
    if saturated:
        rng = np.random.default_rng(seed)
        counts = 1022.0 + rng.integers(0, 2, counts.size)
    newtons = (counts - 100.0) / COUNTS_PER_N
    values = np.column_stack([np.zeros_like(newtons), np.zeros_like(newtons), newtons])
    return CheckRecord(base.ft, Stream(probe.t_s, values), base.windows)


# the load cell's frame: its z along the probe's axis (x_P of eq. 2)
LOADCELL_CLAIMS = Claims(
    ft_rate_hz=200.0,
    probe_rate_hz=50.0,
    R_SP=R_SP_SEED @ np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),
    tool=SEED_TOOL,
)


def _judge_loadcell(rec: CheckRecord):
    f_ref, m = push_pairs(rec, LOADCELL_CLAIMS.R_SP)
    evidence = ProbeEvidence(rec.probe, rec, f_ref, m)
    return check_loadcell(evidence, LOADCELL_CLAIMS, LOADCELL)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_healthy_load_cell_follows_the_pushes(seed):
    verdict = _judge_loadcell(loadcell_record(saturated=False, seed=seed))
    assert verdict.ok, verdict.line()
    response = next(f for f in verdict.findings if f.what == "response")
    assert 0.8 < response.value < 1.2


def test_a_load_cell_whose_z_points_down_the_probe_reads_compression_negative():
    """eq. 3 turns the load cell's z down the probe: compression then reads negative newtons."""
    rec = loadcell_record(saturated=False)
    assert rec.probe is not None
    flipped = CheckRecord(rec.ft, Stream(rec.probe.t_s, -rec.probe.values), rec.windows)
    down = np.diag([-1.0, 1.0, -1.0])  # z_L and x_L turned about y_L
    claims = Claims(200.0, 50.0, LOADCELL_CLAIMS.R_SP @ down, SEED_TOOL)
    spec = LoadCellSpec(counts_of=lambda newtons: 100.0 - COUNTS_PER_N * np.asarray(newtons))
    f_ref, m = push_pairs(flipped, claims.R_SP)
    verdict = check_loadcell(ProbeEvidence(flipped.probe, flipped, f_ref, m), claims, spec)
    assert verdict.ok, verdict.line()


def test_a_saturated_load_cell_says_so_with_its_figure():
    verdict = _judge_loadcell(loadcell_record(saturated=True))
    line = verdict.line()
    assert line.startswith("load cell: FAIL saturated: pushes of "), line
    assert "moved it 1 counts against >= " in line
    assert "% of readings at an ADC rail" in line
