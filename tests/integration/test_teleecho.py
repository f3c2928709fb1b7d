"""Seed 001's press-and-slide on the Panda under Cartesian impedance, and on the UR5 under
position-based impedance: whole scenarios, both engines."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.cosim.engines import simulate
from hoh_cosim.cosim.report import compute_report
from hoh_cosim.cosim.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


@pytest.mark.parametrize("name", ["teleecho_slide", "teleecho_slide_ur5"])
def test_the_slide_keeps_contact_with_a_low_steady_force(name):
    scenario = load_scenario(SCENARIOS / f"{name}.yaml")
    rec = simulate(scenario, "inprocess", progress=False)
    m = compute_report(scenario, rec).metrics
    assert m["contact_losses"] == 0
    assert 1.0 < m["contact_force_mean_N"] < 10.0  # pressing, lightly
    assert m["contact_force_std_N"] < 0.1 * m["contact_force_mean_N"]
    assert m["y_tracking_rms_m"] < 2e-3  # of a ±50 mm slide
    assert m["orientation_error_max_rad"] < np.radians(3.0)
    # the probe pressed in from the approach on, and stayed in through three periods of the slide
    depth = rec["plant.penetration"][:, 0]
    sliding = rec.time >= 6.0
    assert np.all(depth[sliding] > 1e-3)
    # and it did slide the whole amplitude
    y = rec["plant.p_BT_B"][sliding, 1]
    assert np.ptp(y) == pytest.approx(0.10, abs=0.005)


@pytest.mark.parametrize(
    ("name", "low", "high"), [("teleecho_slide", 200.0, 1e4), ("teleecho_slide_ur5", 95.0, 105.0)]
)
def test_the_apparent_stiffness_against_the_phantom(name, low, high):
    """Pressed and settled (7 s after the press, no slide): the UR5's admittance renders K_z =
    100 N/m, so the force is K_z times how far the reference lies below the tip; the Panda's law has
    no force feedback and eq. 6 weighs the force by the arm's own inertia B_A, so it presses several
    times harder for the same gap."""
    scenario = load_scenario(
        SCENARIOS / f"{name}.yaml", duration_s=10.0, overrides=["controller.task.slide_start_s=100"]
    )
    rec = simulate(scenario, "inprocess", progress=False)
    gap = -rec["controller.pose_error"][-1, 2]  # the reference below the tip [m]
    force = rec["plant.F_contact_B"][-1, 2]
    assert gap > 0.005
    assert low < force / gap < high


def test_fmu_and_inprocess_runs_agree():
    scenario = load_scenario(
        SCENARIOS / "teleecho_slide.yaml",
        duration_s=4.0,
        overrides=["controller.task.approach_start_s=0.5", "controller.task.slide_start_s=1.0"],
    )
    fmu = simulate(scenario, "fmu", progress=False)
    inprocess = simulate(scenario, "inprocess", progress=False)
    assert fmu.columns == inprocess.columns
    assert np.max(np.abs(fmu.values - inprocess.values)) <= 1e-9
    assert np.max(fmu["plant.penetration"]) > 0.0  # it reached the phantom
