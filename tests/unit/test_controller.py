"""The HandGuidingController block: law, contact compensation, fixture, limits and stops."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hoh_cosim.control.block import zero_inputs
from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.supervisor import LimitParams, Status
from hoh_cosim.errors import ConfigError
from tests.estimates import controller_inputs

DT = 2e-3  # a 500 Hz robot


inputs = controller_inputs


def settle(ctl, seconds=1.0, **overrides):
    out = None
    for k in range(int(seconds / DT)):
        out = ctl.step(k * DT, DT, inputs(**overrides))
    return out


def test_outputs_match_the_declared_ports():
    ctl = HandGuidingController()
    out = ctl.step(0.0, DT, zero_inputs(ctl) | {"ready": np.array([1.0])})
    assert set(out) == {p.name for p in ctl.outputs}
    for port in ctl.outputs:
        assert out[port.name].shape == (port.size,)


def test_in_air_push_gives_the_eq10_speed():
    out = settle(HandGuidingController(), F_hand_B=[3.0, -2.0, 1.0])
    expected = 0.0125 * np.array([3.0 - 0.95, -(2.0 - 0.95), 1.0 - 0.25])
    np.testing.assert_allclose(out["twist_B"][:3], expected, atol=1e-12)
    np.testing.assert_allclose(out["twist_law_B"][:3], expected, atol=1e-12)
    assert Status(int(out["status"][0])) == Status(0)


def test_torque_turns_the_probe():
    out = settle(HandGuidingController(), tau_hand_B=[0.0, 0.0, 0.5])
    np.testing.assert_allclose(out["twist_B"][3:], [0.0, 0.0, 0.4 * (0.5 - 0.1)], atol=1e-12)


def test_contact_compensation_stops_the_bounce():
    contact = [0.0, 0.0, 10.0]  # the phantom pushes back; the wrist feels the same
    out = settle(HandGuidingController(), F_hand_B=contact, F_probe_B=contact)
    np.testing.assert_array_equal(out["twist_B"], 0.0)
    uncompensated = HandGuidingController(ControllerParams(contact_compensation=False))
    assert settle(uncompensated, F_hand_B=contact, F_probe_B=contact)["twist_B"][2] > 0.05


def test_virtual_fixture_blocks_lifting_in_contact():
    ctl = HandGuidingController(ControllerParams(contact_compensation=False, virtual_fixture=True))
    out = settle(ctl, F_hand_B=[3.0, 0.0, 5.0], F_probe_B=[0.0, 0.0, 5.0])
    assert out["twist_B"][2] == 0.0
    assert out["twist_B"][0] > 0.0  # sliding stays free
    assert Status(int(out["status"][0])) & Status.FIXTURE


def test_speed_is_capped_at_a_tenth_of_a_metre_per_second():
    out = settle(HandGuidingController(), F_hand_B=[60.0, 40.0, 0.0])
    assert np.linalg.norm(out["twist_B"][:3]) == pytest.approx(0.10)
    assert Status(int(out["status"][0])) & Status.SPEED_CLAMPED


def test_acceleration_is_limited_from_rest():
    ctl = HandGuidingController()
    out = ctl.step(0.0, DT, inputs(F_hand_B=[20.0, 0.0, 0.0]))
    assert np.linalg.norm(out["twist_B"][:3]) == pytest.approx(1.0 * DT)  # 1 m/s² · 2 ms
    assert Status(int(out["status"][0])) & Status.ACCEL_CLAMPED


def test_soft_force_cap_stops_pressing_harder():
    ctl = HandGuidingController(ControllerParams(contact_compensation=False))
    out = settle(ctl, F_hand_B=[2.0, 0.0, -10.0], F_probe_B=[0.0, 0.0, 21.0])
    assert out["twist_B"][2] == 0.0  # no further down
    assert out["twist_B"][0] > 0.0
    assert Status(int(out["status"][0])) & Status.FORCE_SOFT_CAP


def test_force_stop_latches_until_reset():
    ctl = HandGuidingController()
    out = ctl.step(0.0, DT, inputs(F_hand_B=[5.0, 0, 0], F_probe_B=[0.0, 0.0, 25.5]))
    assert Status(int(out["status"][0])) & Status.FORCE_STOP
    np.testing.assert_array_equal(out["twist_B"], 0.0)
    out = settle(ctl, F_hand_B=[5.0, 0.0, 0.0])  # the force is gone, the stop stays
    assert Status(int(out["status"][0])) & Status.FORCE_STOP
    np.testing.assert_array_equal(out["twist_B"], 0.0)
    ctl.reset()
    assert settle(ctl, F_hand_B=[5.0, 0.0, 0.0])["twist_B"][0] > 0.0


def test_nan_latches_a_stop():
    ctl = HandGuidingController()
    out = ctl.step(0.0, DT, inputs(F_hand_B=[np.nan, 0.0, 0.0]))
    assert Status(int(out["status"][0])) & Status.NONFINITE
    out = settle(ctl, F_hand_B=[5.0, 0.0, 0.0])
    assert not Status(int(out["status"][0])).ok
    np.testing.assert_array_equal(out["twist_B"], 0.0)


@pytest.mark.parametrize(
    ("overrides", "flag"),
    [
        ({"ft_age": 0.016}, Status.STALE_FT),
        ({"probe_age": 0.061}, Status.STALE_PROBE),
        ({"ready": 0.0}, Status.NOT_READY),
    ],
)
def test_stale_or_unready_data_stops_the_motion_until_it_recovers(overrides, flag):
    ctl = HandGuidingController()
    settle(ctl, F_hand_B=[5.0, 0.0, 0.0])
    out = ctl.step(1.0, DT, inputs(F_hand_B=[5.0, 0.0, 0.0], **overrides))
    np.testing.assert_array_equal(out["twist_B"], 0.0)
    assert Status(int(out["status"][0])) & flag
    out = ctl.step(1.002, DT, inputs(F_hand_B=[5.0, 0.0, 0.0]))  # fresh again: not latched
    assert Status(int(out["status"][0])).ok
    assert 0.0 < out["twist_B"][0] <= 1.0 * DT  # and it ramps up from zero


def test_without_a_probe_sensor_its_age_does_not_matter():
    ctl = HandGuidingController(ControllerParams(use_probe=False))
    out = settle(ctl, F_hand_B=[3.0, 0.0, 0.0], probe_age=100.0, F_probe_B=[0, 0, 30.0])
    assert Status(int(out["status"][0])).ok
    assert out["twist_B"][0] > 0.0


def test_workspace_boundary_stops_outward_motion():
    limits = LimitParams(workspace_min_B=[-0.5, -0.5, 0.1], workspace_max_B=[0.5, 0.5, 0.6])
    ctl = HandGuidingController(ControllerParams(limits=limits))
    out = settle(ctl, F_hand_B=[5.0, 5.0, 0.0], p_BT_B=[0.5, 0.0, 0.3])
    assert out["twist_B"][0] == 0.0
    assert out["twist_B"][1] > 0.0
    assert Status(int(out["status"][0])) & Status.WORKSPACE


def test_params_reject_a_zero_fixture_direction():
    with pytest.raises(ConfigError, match=r"fixture_up_B: expected a non-zero vector"):
        ControllerParams(fixture_up_B=[0.0, 0.0, 0.0])


def test_fixture_direction_is_normalised():
    p = ControllerParams(fixture_up_B=[0.0, 0.0, 2.0])
    np.testing.assert_array_equal(p.fixture_up_B, [0.0, 0.0, 1.0])
    assert dataclasses.replace(p, virtual_fixture=True).virtual_fixture


@pytest.mark.parametrize("law", ["deadband_linear", "isotropic", "sigmoid"])
def test_twist_law_is_each_parts_law(law):
    from hoh_cosim.control.admittance import ROTATION_GAINS, TRANSLATION_GAINS, apply_law

    tr = dataclasses.replace(TRANSLATION_GAINS, law=law)
    rot = dataclasses.replace(ROTATION_GAINS, law=law)
    ctl = HandGuidingController(ControllerParams(translation=tr, rotation=rot))
    F, tau = np.array([3.0, -1.5, 0.8]), np.array([0.3, -0.05, 0.6])
    out = ctl.step(0.0, DT, inputs(F_hand_B=F, tau_hand_B=tau))
    np.testing.assert_allclose(
        out["twist_law_B"], np.concatenate([apply_law(F, tr), apply_law(tau, rot)])
    )


def test_mixed_laws_are_applied_per_part():
    from hoh_cosim.control.admittance import ROTATION_GAINS, apply_law

    rot = dataclasses.replace(ROTATION_GAINS, law="sigmoid")
    ctl = HandGuidingController(ControllerParams(rotation=rot))
    tau = np.array([0.3, -0.05, 0.6])
    out = ctl.step(0.0, DT, inputs(tau_hand_B=tau))
    np.testing.assert_allclose(out["twist_law_B"][3:], apply_law(tau, rot))


def test_the_fixture_along_the_surface_normal_follows_the_contact_force():
    """3.F.3 on a slope: the probe force, 30° off the vertical, is the surface's normal. Pushing the
    probe out of the tilted surface is blocked along that normal with `fixture_normal` = contact;
    the seed's horizontal plane (fixed, up = z) lets the same push lift the probe off the slope."""
    n = np.array([np.sin(np.pi / 6), 0.0, np.cos(np.pi / 6)])
    push = 4.0 * n + np.array([0.0, 3.0, 0.0])  # out of the surface and along it
    contact = 5.0 * n

    def twist(normal: str) -> np.ndarray:
        ctl = HandGuidingController(
            ControllerParams(
                contact_compensation=False, virtual_fixture=True, fixture_normal=normal
            )
        )
        return settle(ctl, F_hand_B=push, F_probe_B=contact)["twist_B"][:3]

    along = twist("contact")
    assert along @ n == pytest.approx(0.0, abs=1e-12)  # nothing out of the surface
    assert abs(along[1]) > 0.01  # sliding along it stays free
    assert twist("fixed") @ n > 0.005  # the horizontal plane leaves the slope's normal free


def test_fixture_normal_is_a_closed_set():
    with pytest.raises(
        ConfigError, match=r"fixture_normal: expected one of fixed, contact, got 'up'"
    ):
        ControllerParams(fixture_normal="up")


def test_the_contact_moment_is_not_the_hands_torque():
    """Eq. 12 for the torque: the contact's moment about the torque's point (the estimator's
    tau_probe_B) is taken out of the torque, so a probe pressed with no twist does not turn."""
    moment = [0.0, 0.8, 0.0]  # a sideways contact force 0.11 m below the handle
    out = settle(HandGuidingController(), tau_hand_B=moment, tau_probe_B=moment)
    np.testing.assert_array_equal(out["twist_B"][3:], 0.0)
    off = HandGuidingController(ControllerParams(contact_torque=False))
    assert settle(off, tau_hand_B=moment, tau_probe_B=moment)["twist_B"][4] > 0.2
