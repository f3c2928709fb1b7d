"""The view's geometry and tracks (hoh_cosim.view.scene, hoh_cosim.view.track): pure numpy,
checked against the plant's pinocchio model of the same UR5 and tool."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from hoh_cosim.errors import ConfigError
from hoh_cosim.hardware.session_log import CycleRow
from hoh_cosim.view import REQUIREMENT, require_rerun
from hoh_cosim.view.scene import (
    ArmTracker,
    Surface,
    ToolGeometry,
    link_frames,
    link_poses,
    rotation_z_to,
    tcp_pose,
)
from hoh_cosim.view.track import Track, cosim_roles, rows_track
from plant_models.arm import HOME_Q


def _pinocchio_tcp(q: np.ndarray) -> np.ndarray:
    from plant_models.tool import ToolModel
    from plant_models.ur5 import FramePlacement, UR5Model

    frames = tuple(FramePlacement(n, p, R) for n, (p, R) in ToolModel().flange_frames().items())
    model = UR5Model(frames)
    model.update(q, np.zeros(6), np.zeros(6))
    return model.homogeneous("tcp")


def test_the_drawn_arm_puts_the_tcp_where_the_plant_model_does(rng):
    pytest.importorskip("pinocchio")
    tool = ToolGeometry.of()
    for q in [HOME_Q, *(HOME_Q + rng.uniform(-1.0, 1.0, 6) for _ in range(5))]:
        assert np.allclose(tcp_pose(q, tool), _pinocchio_tcp(np.asarray(q)), atol=1e-12)


def test_each_link_frame_turns_about_its_joint_axis():
    """L_i = T_B,i-1 · Rz(q_i): turning joint i turns L_i about its own z, and moves no frame
    before it."""
    q = np.array(HOME_Q)
    links, _ = link_frames(q)
    for i in range(6):
        turned = q.copy()
        turned[i] += 0.3
        moved, _ = link_frames(turned)
        for j in range(i):
            assert np.allclose(moved[j], links[j])
        assert np.allclose(moved[i][:3, 3], links[i][:3, 3])  # the joint's origin stays
        assert np.allclose(moved[i][:3, 2], links[i][:3, 2])  # and so does its axis


def test_the_tool_geometry_runs_down_the_probe_from_flange_to_tip():
    tool = ToolGeometry.of()
    # flange, wrist sensor, probe sensor, handle, tip: in that order along T's z, tip at 0
    z = [tool.p_TE_T[2], tool.p_TS_T[2], tool.p_TP_T[2], tool.p_TH_T[2], 0.0]
    assert z == sorted(z)
    assert tool.p_TE_T[2] == pytest.approx(-0.2375)
    assert tool.p_TH_T[2] == pytest.approx(-0.11)


def test_the_tracker_follows_a_moving_tcp_on_the_arm_s_own_branch(rng):
    """Joints from TCP poses alone (a session logs no joints): a smooth motion away from home,
    tracked frame after frame, gives back the joints that made it."""
    tool = ToolGeometry.of()
    steps = np.cumsum(rng.normal(0.0, 0.01, (200, 6)), axis=0)
    q_true = HOME_Q + steps
    poses = np.array([tcp_pose(q, tool) for q in q_true])
    q = ArmTracker(tool).track(poses)
    assert np.max(np.abs(q - q_true)) < 1e-6
    assert np.max(np.abs(np.array([tcp_pose(x, tool) for x in q]) - poses)) < 1e-6  # its tol


def test_the_tracker_keeps_its_last_joints_for_a_pose_it_cannot_reach():
    tool = ToolGeometry.of()
    tracker = ArmTracker(tool, max_iterations=5)
    far = tcp_pose(HOME_Q, tool)
    far[:3, 3] = [5.0, 5.0, 5.0]  # 7 m from the base: out of reach
    q = tracker.solve(far)
    assert np.all(np.isfinite(q))
    assert np.allclose(tracker.q, q)


@pytest.mark.parametrize(
    "direction", [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0.3, -0.4, 0.866], [-1e-9, 0, -1]]
)
def test_rotation_z_to_turns_z_onto_the_direction(direction):
    from scipy.spatial.transform import Rotation

    d = np.asarray(direction, dtype=float)
    d /= np.linalg.norm(d)
    R = Rotation.from_quat(rotation_z_to(d)).as_matrix()
    assert np.allclose(R @ [0, 0, 1], d, atol=1e-9)


def test_a_surface_comes_from_the_phantom_and_none_from_no_phantom():
    from plant_models.tissue import PhantomParams

    assert Surface.of(None) is None
    assert Surface.of(PhantomParams(shape="none")) is None
    plane = Surface.of(PhantomParams(plane_point_B=[0.0, 0.0, 0.2]))
    assert plane is not None
    assert plane.shape == "plane"
    assert plane.point_B.tolist() == [0.0, 0.0, 0.2]
    ellipsoid = Surface.of(PhantomParams(shape="ellipsoid"))
    assert ellipsoid is not None
    assert ellipsoid.point_B.tolist() == [-0.10, -0.45, -0.05]


def test_a_run_s_columns_come_from_the_components_it_has():
    circles = {
        "operator": "operator",
        "plant": "plant",
        "ft150": "ft150",
        "estimator": "estimator",
        "controller": "controller",
    }
    roles = cosim_roles(circles)
    assert roles["q"] == "plant.q"
    assert roles["F_hand_B"] == "operator.F_hand_B"
    assert roles["F_hand_est_B"] == "estimator.F_hand_B"
    assert roles["twist_cmd_B"] == "controller.twist_B"
    assert "surface_offset_m" not in roles
    freehand = cosim_roles({"breathing": "breathing", "operator": "operator", "hand": "freehand"})
    assert freehand["p_BT_B"] == "hand.p_BT_B"
    assert freehand["surface_offset_m"] == "breathing.offset_m"
    assert "q" not in freehand
    assert "twist_cmd_B" not in freehand
    assert cosim_roles({"operator": "operator", "estimator": "estimator"}) == {}


def test_the_runner_s_rows_make_a_track_in_the_base_frame():
    from hoh_cosim.control.frames import rotvec_to_matrix

    row = CycleRow()
    rows = []
    for k in range(3):
        row.start(k, 0.02 * k, True, True)
        row.set("/robot.p_BT_B", [0.1 * k, -0.45, 0.25])
        row.set("/robot.rotvec_BT", [np.pi, 0.0, 0.1 * k])
        row.set("/robot.twist_B", [0.01, 0.0, 0.0, 0.0, 0.0, 0.0])
        row.set("/estimate.F_hand_B", [1.0, 2.0, 3.0])
        row.set("/estimate.F_probe_B", [0.0, 0.0, 4.0])
        row.set("/command.sent_B", [0.02, 0.0, 0.0, 0.0, 0.0, 0.1])
        row.set("/command.status", 16)
        row.set("/command.mode", 2)
        rows.append(row.values.copy())
    track = rows_track(np.array(rows))
    assert track.t.tolist() == [0.0, 0.02, 0.04]
    assert track.p_BT_B[2].tolist() == [0.2, -0.45, 0.25]
    assert np.allclose(track.R_BT[1], rotvec_to_matrix([np.pi, 0.0, 0.1]))
    assert track.F_contact_B[0].tolist() == [0.0, 0.0, 4.0]
    assert track.v_B[0].tolist() == [0.01, 0.0, 0.0]
    assert track.status.tolist() == [16.0] * 3
    assert track.q is None  # found from the poses by the view's tracker


def test_tracks_are_cut_and_joined_column_by_column():
    n = 4
    track = Track(
        t=np.arange(n) * 0.1,
        p_BT_B=np.zeros((n, 3)),
        R_BT=np.tile(np.eye(3), (n, 1, 1)),
        status=np.arange(n, dtype=float),
    )
    head, tail = track.rows(slice(0, 1)), track.rows(slice(1, None))
    assert len(head) == 1
    assert len(tail) == 3
    joined = Track.concatenate([head, tail])
    assert np.array_equal(joined.t, track.t)
    assert np.array_equal(joined.status, track.status)
    assert joined.q is None


def test_without_rerun_the_view_names_the_command_that_installs_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)  # as if not installed
    with pytest.raises(ConfigError, match=r"--view needs Rerun \(the view extra\)") as error:
        require_rerun("--view")
    assert str(error.value).endswith(f"-m pip install '{REQUIREMENT}'")


def test_the_links_of_many_poses_at_once_are_those_of_each_alone(rng):
    q = HOME_Q + rng.uniform(-2.0, 2.0, (20, 6))
    each = np.array([link_frames(x)[0] for x in q])
    assert np.allclose(link_poses(q), each, atol=1e-14)
