"""The freehand probe: the hand alone carries the probe's weight, its inertia and the contact."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.vectors import GRAVITY_B
from hoh_cosim.errors import ConfigError
from plant_models.freehand import HOME_R_BT, HOME_TIP_B, FreehandParams, FreehandProbe
from plant_models.operator import Operator, OperatorParams
from plant_models.plant import Plant
from plant_models.tissue import PhantomParams
from plant_models.tool import ToolModel

Z3 = np.zeros(3)
MASS = ToolModel().mass_kg
WEIGHT_B = MASS * GRAVITY_B
AIR = PhantomParams(shape="none")
ON = np.array([1.0])


def hand_in_the_loop(
    params: FreehandParams, operator: OperatorParams, seconds: float, dt: float = 2e-3
) -> dict[str, np.ndarray]:
    """The operator holding the freehand probe, as clinical_freehand.yaml wires them."""
    probe = FreehandProbe(params)
    hand = Operator(operator, rng=np.random.default_rng(5))
    out = probe.initial_outputs()
    rows: dict[str, list] = {"t": [], "p": [], "F": [], "contact": [], "R": [], "grip": []}
    for k in range(round(seconds / dt)):
        h = hand.step(
            k * dt,
            dt,
            {"p_BT_B": out["p_BT_B"], "twist_B": out["twist_B"], "F_contact_B": out["F_contact_B"]},
        )
        out = probe.step(
            k * dt,
            dt,
            {
                "F_hand_B": h["F_hand_B"],
                "tau_hand_B": h["tau_hand_B"],
                "F_tip_B": Z3,
                "hand_on": h["hand_on"],
            },
        )
        for key, value in (
            ("t", (k + 1) * dt),
            ("p", out["p_BT_B"]),
            ("F", h["F_hand_B"]),
            ("contact", out["F_contact_B"]),
            ("R", out["R_BT"]),
            ("grip", out["tau_grip_B"]),
        ):
            rows[key].append(np.copy(value))
    return {k: np.array(v) for k, v in rows.items()}


def test_it_starts_where_the_robot_starts() -> None:
    robot = Plant().initial_outputs()
    probe = FreehandProbe().initial_outputs()
    np.testing.assert_allclose(HOME_TIP_B, robot["p_BT_B"], atol=1e-12)
    np.testing.assert_allclose(HOME_R_BT.reshape(9), robot["R_BT"], atol=1e-12)
    np.testing.assert_allclose(probe["p_BT_B"], robot["p_BT_B"], atol=1e-12)
    np.testing.assert_allclose(probe["R_BT"], robot["R_BT"], atol=1e-12)


def test_held_in_the_air_the_hand_carries_exactly_the_weight() -> None:
    """With the feed-forward of the known weight the probe stays where it is and the hand's force
    is -m g; the grip holds the weight's moment too, so nothing tilts."""
    held = hand_in_the_loop(
        FreehandParams(phantom=AIR),
        OperatorParams(task="hold", intrinsic=True, feedforward_B=-WEIGHT_B),
        3.0,
    )
    np.testing.assert_allclose(held["F"][-1], -WEIGHT_B, atol=1e-9)
    assert np.max(np.linalg.norm(held["p"] - HOME_TIP_B, axis=1)) < 1e-9
    np.testing.assert_allclose(held["R"][-1], HOME_R_BT.reshape(9), atol=1e-12)


@pytest.mark.parametrize("stiffness", [200.0, 600.0])
def test_without_feed_forward_the_probe_sags_until_the_hand_carries_the_weight(
    stiffness: float,
) -> None:
    """Statics whatever the hand: at rest its force is the probe's weight; without the feed-forward
    the stiffness pays for it, sagging by m g / K."""
    held = hand_in_the_loop(
        FreehandParams(phantom=AIR),
        OperatorParams(task="hold", intrinsic=True, stiffness=stiffness, damping=20.0),
        4.0,
    )
    np.testing.assert_allclose(held["F"][-1], -WEIGHT_B, rtol=1e-4, atol=1e-9)
    sag = HOME_TIP_B[2] - held["p"][-1, 2]
    assert sag == pytest.approx(MASS * 9.81 / stiffness, rel=1e-3)


def test_pressed_onto_the_phantom_the_contact_carries_hand_and_weight() -> None:
    """A constant push down at rest: the phantom pushes back with the push plus the weight."""
    probe = FreehandProbe(FreehandParams(phantom=PhantomParams(plane_point_B=[0.0, 0.0, 0.245])))
    push = np.array([0.0, 0.0, -6.0])
    for k in range(3000):
        out = probe.step(
            k * 2e-3, 2e-3, {"F_hand_B": push, "tau_hand_B": Z3, "F_tip_B": Z3, "hand_on": ON}
        )
    np.testing.assert_allclose(out["F_contact_B"], -(push + WEIGHT_B), atol=1e-6)
    assert np.linalg.norm(out["twist_B"]) < 1e-6


def test_let_go_it_falls() -> None:
    """No hand (no force, no grip): free fall."""
    probe = FreehandProbe(FreehandParams(phantom=AIR))
    for k in range(100):
        out = probe.step(k * 1e-3, 1e-3, {"F_hand_B": Z3, "tau_hand_B": Z3, "F_tip_B": Z3})
    drop = HOME_TIP_B[2] - out["p_BT_B"][2]
    # implicit Euler: g t (t + h) / 2
    assert drop == pytest.approx(0.5 * 9.81 * 0.1 * 0.101, rel=1e-9)


def test_the_grip_tilts_the_probe_by_the_torque_over_its_stiffness() -> None:
    """A sideways push on the tip, held: the probe tilts until the grip's torque balances it."""
    k_grip = 4.0
    side = np.array([0.0, 0.5, 0.0])
    final = {}
    for push in (0.0, 1.0):
        probe = FreehandProbe(FreehandParams(phantom=AIR, grip_stiffness=k_grip, grip_damping=0.05))
        for k in range(1500):
            out = probe.step(
                k * 2e-3,
                2e-3,
                {
                    "F_hand_B": -WEIGHT_B - push * side,
                    "tau_hand_B": Z3,
                    "F_tip_B": push * side,
                    "hand_on": ON,
                },
            )
        final[push] = out
    # the tip is 0.11 m below the handle: a torque of 0.055 N·m about the handle, along x
    lever = -(ToolModel().p_ST_S[2] - ToolModel().p_SH_S[2])
    tilt = math.acos(min(1.0, -final[1.0]["R_BT"][8]))
    assert tilt == pytest.approx(0.5 * lever / k_grip, rel=0.02)
    # the grip answers with that torque (beside the weight's moment it holds in both)
    extra = final[1.0]["tau_grip_B"] - final[0.0]["tau_grip_B"]
    np.testing.assert_allclose(extra, [-0.5 * lever, 0.0, 0.0], atol=0.02 * 0.5 * lever)


def test_breathing_lifts_the_probe_the_hand_presses() -> None:
    """The surface rising under a probe pressed with a constant force carries the probe up with
    it: the contact force stays the push plus the weight."""
    probe = FreehandProbe(FreehandParams(phantom=PhantomParams(plane_point_B=[0.0, 0.0, 0.245])))
    push = np.array([0.0, 0.0, -5.0])
    z = []
    for k in range(4000):
        t = k * 2e-3
        h = 0.005 * (1.0 - math.cos(2.0 * math.pi * 0.25 * t))
        h_dot = 0.005 * 2.0 * math.pi * 0.25 * math.sin(2.0 * math.pi * 0.25 * t)
        out = probe.step(
            t,
            2e-3,
            {
                "F_hand_B": push,
                "tau_hand_B": Z3,
                "F_tip_B": Z3,
                "hand_on": ON,
                "surface_offset_m": np.array([h]),
                "surface_rate_m_s": np.array([h_dot]),
            },
        )
        z.append(out["p_BT_B"][2])
    assert np.ptp(z[2000:]) == pytest.approx(0.010, rel=0.02)  # it rides 10 mm up and down
    assert out["F_contact_B"][2] == pytest.approx(5.0 + MASS * 9.81, rel=0.02)


def test_sampled_steps_are_deterministic() -> None:
    a, b = FreehandProbe(), FreehandProbe()
    push = {"F_hand_B": np.array([0.3, 0.0, 4.0]), "tau_hand_B": Z3, "F_tip_B": Z3, "hand_on": ON}
    for k in range(100):
        out_a, out_b = a.step(k * 2e-3, 2e-3, push), b.step(k * 2e-3, 2e-3, push)
    np.testing.assert_array_equal(out_a["p_BT_B"], out_b["p_BT_B"])
    a.reset()
    np.testing.assert_array_equal(a.outputs_now["p_BT_B"], HOME_TIP_B)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"grip_stiffness": -1.0}, r"grip_stiffness must be >= 0"),
        ({"substep_s": 0.0}, r"substep_s must be > 0"),
        ({"R_BT0": np.eye(3) * 2}, r"R_BT0: not a rotation matrix"),
    ],
)
def test_bad_parameters_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        FreehandParams(**kwargs)
