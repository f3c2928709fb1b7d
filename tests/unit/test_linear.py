"""The linear analysis: python-control's models of the filters against the filters themselves, and
the loop margins against cases worked by hand."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hoh_cosim.control.baselines import ButterworthParams, OneEuroParams
from hoh_cosim.control.estimator import EstimatorParams, make_filter_bank
from hoh_cosim.cosim.metrics import sinusoid_phase
from hoh_cosim.cosim.scenario import load_scenario
from hoh_cosim.study.linear import (
    OMEGA,
    LoopModel,
    filter_response,
    frd_margins,
    lag_ms,
    loop_margins,
    loop_model,
    open_loop,
)
from tests.integration.test_scenarios import SCENARIOS

DT = 0.001
TICKS = 5  # FT-150 packets every 5 ms


def _measured(params: EstimatorParams, frequency_hz: float) -> tuple[float, float]:
    """Gain and lag [ms] of the estimator's hand-force filter against the held raw packets, from
    20 s of a sinusoid stepped through the real filter bank."""
    bank = make_filter_bank(params)
    n = 20_000
    t = np.arange(n) * DT
    z = np.sin(2 * math.pi * frequency_hz * t)
    out, held = np.empty(n), np.empty(n)
    value = 0.0
    for k in range(n):
        packet = None
        if k % TICKS == 0:
            value = z[k]
            packet = np.array([value, 0.0, 0.0])
        out[k] = bank.step_bank(DT, [packet, None, None])[0]
        held[k] = value
    late = slice(n // 2, None)
    a_raw, phi_raw = sinusoid_phase(t[late], held[late], frequency_hz)
    a_out, phi_out = sinusoid_phase(t[late], out[late], frequency_hz)
    dphi = (phi_raw - phi_out + math.pi) % (2 * math.pi) - math.pi
    return a_out / a_raw, 1e3 * dphi / (2 * math.pi * frequency_hz)


FILTERS = {
    "kalman": EstimatorParams(filter="kalman"),
    "lead_lowpass": EstimatorParams(filter="lead_lowpass"),
    "butterworth": EstimatorParams(
        filter="butterworth", butterworth=ButterworthParams(order=5, cutoff_hz=5.0)
    ),
    # with beta = 0 the 1-euro filter is exactly linear
    "one_euro": EstimatorParams(
        filter="one_euro", one_euro_force=OneEuroParams(min_cutoff_hz=2.0, beta=0.0)
    ),
    "none": EstimatorParams(filter="none"),
}


@pytest.mark.parametrize("kind", FILTERS)
@pytest.mark.parametrize("frequency_hz", [0.25, 1.8, 6.0])
def test_the_linear_model_is_the_filter(kind: str, frequency_hz: float) -> None:
    params = FILTERS[kind]
    w = 2 * math.pi * frequency_hz
    g = filter_response(params, np.array([w]))[0]
    gain, lag = _measured(params, frequency_hz)
    assert abs(g) == pytest.approx(gain, rel=2e-3)
    assert lag_ms(g, w) == pytest.approx(lag, abs=0.1)


def test_the_default_kalman_leads_and_peaks() -> None:
    """What the report says about the defaults: a lead at the circle frequency (the circles run
    measures -3.6 ms) and a gain peak of about 1.6 near 2 Hz."""
    params = EstimatorParams()
    w0 = 2 * math.pi * 0.25
    assert lag_ms(filter_response(params, np.array([w0]))[0], w0) == pytest.approx(-3.66, abs=0.05)
    gain = np.abs(filter_response(params, OMEGA))
    assert gain.max() == pytest.approx(1.58, abs=0.02)
    assert 1.2 < OMEGA[np.argmax(gain)] / (2 * math.pi) < 2.5


def test_the_lead_lowpass_has_no_peak_and_little_lag_at_the_circles() -> None:
    """The filter without a peak (control/filters.py): gain <= 1.1 at every frequency up to the
    packets' Nyquist, at most 5 ms behind the held reading at the circles' 0.25 Hz, and a better
    gain margin than the Kalman filter's on the default loop."""
    params = EstimatorParams(filter="lead_lowpass")
    assert np.abs(filter_response(params, OMEGA)).max() <= 1.1
    w0 = 2 * math.pi * 0.25
    assert 0.0 < lag_ms(filter_response(params, np.array([w0]))[0], w0) <= 5.0
    model = LoopModel(0.0125, 300.0, 20.0, 0.15, 0.004, 0.016)
    lead = loop_margins(model, filter_response(params, OMEGA), OMEGA)
    kalman = loop_margins(model, filter_response(EstimatorParams(), OMEGA), OMEGA)
    assert lead.gain_margin >= 2.0 > 1.6 > kalman.gain_margin
    assert lead.phase_margin_deg >= 45.0


def test_the_variable_laws_light_schedule_adds_margin_and_a_heavy_one_takes_it() -> None:
    """Linearised about the tuned circles' push (about 10 deadbands), the default k = 0.05 is a
    lead that raises the gain margin over eq. 10's; k = 0.2 lowers it."""
    from hoh_cosim.control.variable_admittance import VariableAdmittanceParams
    from hoh_cosim.study.linear import variable_law_lead

    model = LoopModel(0.0145, 300.0, 20.0, 0.15, 0.004, 0.016)
    g = filter_response(EstimatorParams(filter="lead_lowpass"), OMEGA)
    excess = 4.8 / 0.45 - 1.0

    def gm(k: float) -> float:
        lead = variable_law_lead(VariableAdmittanceParams(intent_gain=k), excess, OMEGA)
        return loop_margins(model, g * lead, OMEGA).gain_margin

    assert gm(0.05) > 2.0 > gm(0.0) > gm(0.2)


def test_margins_of_an_integrator_with_delay() -> None:
    """L = α K e^{-sT} / s: the phase reaches -180° at ω = π / (2T), where |L| = α K / ω, so the
    loop loses stability at α = π / (2 T K); the phase margin is 90° - ω_c T · 180/π at ω_c = α K."""
    model = LoopModel(
        slope=0.01,
        hand_stiffness=300.0,
        hand_damping=0.0,
        hand_delay_s=0.15,
        sensor_delay_s=0.0,
        robot_delay_s=0.0,
    )
    margins = loop_margins(model, np.ones(len(OMEGA), dtype=complex), OMEGA)
    assert margins.critical_slope == pytest.approx(math.pi / (2 * 0.15 * 300.0), rel=1e-4)
    assert margins.phase_crossover_rad_s == pytest.approx(math.pi / 0.3, rel=1e-4)
    assert margins.phase_margin_deg == pytest.approx(90.0 - math.degrees(3.0 * 0.15), abs=0.01)


def test_the_gain_margin_is_inverse_in_the_slope() -> None:
    scenario = load_scenario(SCENARIOS / "circles.yaml")
    model = loop_model(scenario)
    gain = filter_response(scenario.component_of_kind("estimator").params, OMEGA)
    base = loop_margins(model, gain, OMEGA)
    double = loop_margins(dataclasses.replace(model, slope=2 * model.slope), gain, OMEGA)
    assert double.gain_margin == pytest.approx(base.gain_margin / 2, rel=1e-6)
    assert double.critical_slope == pytest.approx(base.critical_slope, rel=1e-6)


def test_loop_model_reads_the_scenario() -> None:
    model = loop_model(load_scenario(SCENARIOS / "circles.yaml"))
    assert model.slope == 0.0125
    assert model.hand_delay_s == 0.15
    # FT-150 latency 2 ms + the held packet's mean age 2 ms; CB3 one 8 ms cycle + 4 ms + 4 ms
    assert model.sensor_delay_s == pytest.approx(0.004)
    assert model.robot_delay_s == pytest.approx(0.016)


def test_an_intrinsic_hands_stiffness_is_not_delayed() -> None:
    """The clinical study's hand is `intrinsic`: its stiffness and damping act on the tip as it is,
    only its press loop waits for its reaction. The loop model then has no hand delay, and the
    same hand with the delay (`intrinsic` false) loses stability at a slope several times smaller."""
    path = SCENARIOS / "clinical_assisted.yaml"
    intrinsic = load_scenario(path)
    delayed = load_scenario(path, ["operator.intrinsic=false"])
    assert intrinsic.component_of_kind("operator").params.intrinsic
    reaction = delayed.component_of_kind("operator").params.reaction_delay_s
    assert reaction > 0.05
    assert loop_model(intrinsic).hand_delay_s == 0.0
    assert loop_model(delayed).hand_delay_s == reaction
    gain = filter_response(intrinsic.component_of_kind("estimator").params, OMEGA)
    fast = loop_margins(loop_model(intrinsic), gain, OMEGA).critical_slope
    slow = loop_margins(loop_model(delayed), gain, OMEGA).critical_slope
    assert fast > 3.0 * slow


@pytest.mark.parametrize("kind", sorted(FILTERS))
@pytest.mark.parametrize("slope", [0.002, 0.0125, 0.2])
def test_frd_margins_are_python_controls_to_the_bit(kind: str, slope: float) -> None:
    """`frd_margins` skips only the stability margin of python-control's `stability_margins`: every
    gain and phase margin and both crossovers' frequencies come out bit for bit the same, on loops
    with one crossover, many (a large slope) or none."""
    import control

    model = dataclasses.replace(loop_model(load_scenario(SCENARIOS / "circles.yaml")), slope=slope)
    loop = open_loop(model, filter_response(FILTERS[kind], OMEGA, signal_speed=6.0), OMEGA)
    gm, pm, _, wpc, wgc, _ = control.stability_margins(loop, returnall=True)
    ours = frd_margins(loop)
    theirs = [np.asarray(v, dtype=float) for v in (gm, pm, wpc, wgc)]
    assert theirs[0].size > 0 or slope == 0.002
    for a, b in zip(ours, theirs, strict=True):
        assert a.shape == b.shape
        assert np.array_equal(a, b)
