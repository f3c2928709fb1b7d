"""The gravity-calibration pose sequencer: poses, servo, settle and hold timing, limits.

The sequencer is driven through a kinematic arm written here: the commanded twist is integrated
into the TCP pose, p <- p + v dt and R <- exp([ω dt]×) R (ω in the base frame, as speedL takes it).
Times are binary fractions so that every phase boundary falls exactly on a tick.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import pytest

from hoh_cosim.control.frames import matrix_to_rotvec, rotvec_to_matrix
from hoh_cosim.control.sequencer import PoseSequencer, SequencerParams, tilted_orientations
from hoh_cosim.errors import ConfigError

DT = 1.0 / 128.0
FAST = SequencerParams(
    tilts=2,
    tilt_min_deg=10.0,
    tilt_max_deg=25.0,
    directions=3,
    move_s=1.0,
    settle_s=0.125,
    hold_s=0.25,
    gain_position=10.0,
    gain_orientation=10.0,
    max_linear_speed=0.05,
    max_angular_speed=2.0,
)  # 6 poses of 1.375 s
P0 = np.array([0.4, -0.1, 0.3])
R0 = rotvec_to_matrix([math.pi, 0.0, 0.0])  # the probe pointing down, as on the UR5


def angle_between(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(np.linalg.norm(matrix_to_rotvec(Ra @ Rb.T)))


def expected_target(R_start: np.ndarray, tilt_deg: float, k: int, directions: int) -> np.ndarray:
    azimuth = 2.0 * math.pi * k / directions
    axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
    return rotvec_to_matrix(math.radians(tilt_deg) * axis) @ R_start


@dataclass
class Tick:
    t_end: float
    twist: np.ndarray
    pose_index: int
    holding: float
    done: float
    p: np.ndarray  # the TCP pose at t_end, after the twist was applied over the tick
    R: np.ndarray


def drive(params, seconds, p0=P0, R0=R0, bump=None):
    """Step the sequencer and integrate its twist; `bump(k, p)` may push the TCP after tick k."""
    seq = PoseSequencer(params)
    p, R = p0.copy(), R0.copy()
    ticks = []
    for k in range(round(seconds / DT)):
        out = seq.step(k * DT, DT, {"p_BT_B": p.copy(), "R_BT": R.reshape(9).copy()})
        twist = out["twist_B"].copy()
        p = p + twist[:3] * DT
        R = rotvec_to_matrix(twist[3:] * DT) @ R
        if bump is not None:
            p = bump(k, p)
        ticks.append(
            Tick(
                (k + 1) * DT,
                twist,
                int(out["pose_index"][0]),
                float(out["holding"][0]),
                float(out["done"][0]),
                p.copy(),
                R.copy(),
            )
        )
    return ticks


@pytest.fixture(scope="module")
def fast_run():
    return drive(FAST, FAST.n_poses * FAST.pose_s + 0.5)


# --- the poses --------------------------------------------------------------------------------


def test_default_is_32_poses_of_4_tilts_in_8_directions():
    params = SequencerParams()
    assert params.n_poses == 32
    assert params.pose_s == 3.0 + 0.5 + 5.0
    targets = tilted_orientations(np.eye(3), params)
    assert len(targets) == 32
    tilts = [round(math.degrees(angle_between(R, np.eye(3))), 9) for R in targets]
    assert tilts == [15.0] * 8 + [30.0] * 8 + [45.0] * 8 + [60.0] * 8
    # every pose is different
    for i in range(32):
        for j in range(i):
            assert angle_between(targets[i], targets[j]) > 0.1


def test_tilted_orientations_tilt_the_start_about_horizontal_axes(rng):
    R_start = rotvec_to_matrix(rng.normal(size=3))
    params = SequencerParams(tilts=3, tilt_min_deg=20.0, tilt_max_deg=110.0, directions=5)
    targets = tilted_orientations(R_start, params)
    assert len(targets) == 15
    for n, R in enumerate(targets):
        tilt, k = params.tilts_deg[n // 5], n % 5
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        # the rotation from the start, in the base frame: angle the tilt, axis horizontal
        r = matrix_to_rotvec(R @ R_start.T)
        assert np.linalg.norm(r) == pytest.approx(math.radians(tilt), abs=1e-12)
        assert r[2] == pytest.approx(0.0, abs=1e-12)
        azimuth = 2.0 * math.pi * k / 5  # the directions evenly spaced, the first along x
        np.testing.assert_allclose(
            r / np.linalg.norm(r), [math.cos(azimuth), math.sin(azimuth), 0.0], atol=1e-12
        )
        np.testing.assert_allclose(R, expected_target(R_start, tilt, k, 5), atol=1e-12)


def test_a_tilt_tips_the_tool_axis_away_from_where_it_pointed():
    # the probe pointing down; each pose tips its axis by the tilt from the vertical
    params = SequencerParams(tilts=1, tilt_min_deg=30.0, tilt_max_deg=30.0, directions=4)
    for R in tilted_orientations(R0, params):
        down = R[:, 2]  # the TCP z axis in the base frame
        assert math.degrees(math.acos(-down[2])) == pytest.approx(30.0)


# --- driving through the poses ----------------------------------------------------------------


def test_outputs_match_the_declared_ports():
    seq = PoseSequencer(FAST)
    out = seq.step(0.0, DT, {"p_BT_B": P0, "R_BT": R0.reshape(9)})
    assert set(out) == {port.name for port in seq.outputs}
    for port in seq.outputs:
        assert out[port.name].shape == (port.size,)


def test_pose_index_counts_every_pose_in_order(fast_run):
    indices = [tick.pose_index for tick in fast_run]
    visited = [i for n, i in enumerate(indices) if n == 0 or i != indices[n - 1]]
    assert visited == list(range(1, FAST.n_poses + 1))
    pose_s = Fraction(FAST.pose_s)
    for tick in fast_run:
        expected = min(int(Fraction(tick.t_end) // pose_s) + 1, FAST.n_poses)
        assert tick.pose_index == expected, tick.t_end


def test_holding_only_after_move_and_settle_within_each_pose(fast_run):
    pose_s = Fraction(FAST.pose_s)
    hold_from = Fraction(FAST.move_s + FAST.settle_s)
    held_ticks = dict.fromkeys(range(1, FAST.n_poses + 1), 0)
    for tick in fast_run:
        t_end = Fraction(tick.t_end)
        phase = t_end % pose_s
        in_sequence = t_end < FAST.n_poses * pose_s
        assert tick.holding == (1.0 if in_sequence and phase >= hold_from else 0.0), tick.t_end
        if tick.holding:
            held_ticks[tick.pose_index] += 1
    # every pose is held for hold_s
    assert set(held_ticks.values()) == {round(FAST.hold_s / DT)}


def test_the_twist_is_zero_from_the_end_of_each_move(fast_run):
    moving = 0
    for tick in fast_run:
        phase = Fraction(tick.t_end) % Fraction(FAST.pose_s)
        if phase >= Fraction(FAST.move_s) or tick.done:
            np.testing.assert_array_equal(tick.twist, np.zeros(6))
        elif np.any(tick.twist != 0.0):
            moving += 1
    assert moving > 0.5 * FAST.n_poses * FAST.move_s / DT


def test_each_hold_is_at_the_target_orientation_and_the_start_position(fast_run):
    holds = [tick for tick in fast_run if tick.holding]
    assert holds
    for tick in holds:
        n = tick.pose_index - 1
        target = expected_target(R0, FAST.tilts_deg[n // 3], n % 3, 3)
        assert math.degrees(angle_between(tick.R, target)) < 0.05, tick.pose_index
        np.testing.assert_allclose(tick.p, P0, atol=1e-12)
        # and so the tilt from the start is the pose's tilt
        tilt = math.degrees(angle_between(tick.R, R0))
        assert tilt == pytest.approx(FAST.tilts_deg[n // 3], abs=0.05)


def test_the_orientation_stays_put_through_settle_and_hold(fast_run):
    by_pose: dict[int, list[np.ndarray]] = {}
    for tick in fast_run:
        phase = Fraction(tick.t_end) % Fraction(FAST.pose_s)
        if phase >= Fraction(FAST.move_s) and not tick.done:
            by_pose.setdefault(tick.pose_index, []).append(tick.R)
    assert len(by_pose) == FAST.n_poses
    for Rs in by_pose.values():
        for R in Rs[1:]:
            assert angle_between(R, Rs[0]) < 1e-12


def test_done_after_every_pose_with_a_zero_twist(fast_run):
    end = Fraction(FAST.n_poses) * Fraction(FAST.pose_s)
    after = [tick for tick in fast_run if Fraction(tick.t_end) >= end]
    before = [tick for tick in fast_run if Fraction(tick.t_end) < end]
    assert after  # the run goes beyond the last pose
    assert all(tick.done == 0.0 for tick in before)
    for tick in after:
        assert tick.done == 1.0
        assert tick.holding == 0.0
        assert tick.pose_index == FAST.n_poses
        np.testing.assert_array_equal(tick.twist, np.zeros(6))
    # the arm stays where the last pose left it
    np.testing.assert_allclose(after[-1].R, before[-1].R, atol=1e-12)


def test_the_schedule_starts_at_the_first_step():
    # a sequencer first stepped at t = 100 s begins with the first move, not 11 poses in
    seq = PoseSequencer(SequencerParams())
    inputs = {"p_BT_B": P0, "R_BT": R0.reshape(9)}
    out = seq.step(100.0, DT, inputs)
    assert out["pose_index"][0] == 1.0
    assert out["holding"][0] == 0.0
    assert np.linalg.norm(out["twist_B"][3:]) > 0.0  # moving towards the first tilt
    out = seq.step(100.0 + 3.0 + 0.5 + 1.0, DT, inputs)  # 1 s into the first hold
    assert (out["pose_index"][0], out["holding"][0]) == (1.0, 1.0)
    out = seq.step(100.0 + 32 * 8.5, DT, inputs)
    assert out["done"][0] == 1.0
    assert out["pose_index"][0] == 32.0
    np.testing.assert_array_equal(out["twist_B"], np.zeros(6))
    seq.reset()  # and after a reset, from the next step
    out = seq.step(500.0, DT, inputs)
    assert (out["pose_index"][0], out["done"][0]) == (1.0, 0.0)


def test_the_angular_speed_limit_holds_in_every_command():
    params = SequencerParams(
        tilts=1,
        tilt_min_deg=40.0,
        tilt_max_deg=40.0,
        directions=2,
        move_s=3.0,
        settle_s=0.0,
        hold_s=0.125,
        gain_orientation=10.0,
        max_angular_speed=0.6,
    )
    ticks = drive(params, params.n_poses * params.pose_s)
    speeds = np.array([np.linalg.norm(tick.twist[3:]) for tick in ticks])
    assert np.all(speeds <= 0.6 * (1.0 + 1e-12))
    assert speeds.max() == pytest.approx(0.6)  # the limit was reached, not just respected
    # it still arrives: 40 degrees, then 80 degrees across, at 0.6 rad/s
    hold = [tick for tick in ticks if tick.holding]
    assert hold
    for tick in hold:
        target = expected_target(R0, 40.0, tick.pose_index - 1, 2)
        assert math.degrees(angle_between(tick.R, target)) < 0.05


def test_the_linear_speed_limit_holds_while_returning_to_the_start():
    params = SequencerParams(
        tilts=1,
        tilt_min_deg=10.0,
        tilt_max_deg=10.0,
        directions=1,
        move_s=4.0,
        settle_s=0.125,
        hold_s=0.25,
        gain_position=10.0,
        max_linear_speed=0.05,
    )
    push = np.array([0.06, -0.08, 0.0])  # 10 cm off, after the first tick

    def bump(k, p):
        return p + push if k == 0 else p

    ticks = drive(params, params.pose_s, bump=bump)
    speeds = np.array([np.linalg.norm(tick.twist[:3]) for tick in ticks])
    assert np.all(speeds <= 0.05 * (1.0 + 1e-12))
    assert speeds.max() == pytest.approx(0.05)
    # the servo pushes back towards the start, straight along the push
    first = ticks[1].twist[:3]
    np.testing.assert_allclose(first / np.linalg.norm(first), -push / np.linalg.norm(push))
    for tick in ticks:
        if tick.holding:
            np.testing.assert_allclose(tick.p, P0, atol=1e-6)


def test_the_first_command_turns_towards_the_first_direction():
    params = SequencerParams(gain_orientation=2.0, max_angular_speed=0.1)
    seq = PoseSequencer(params)
    R_start = rotvec_to_matrix([0.3, -0.2, 2.0])
    out = seq.step(0.0, DT, {"p_BT_B": P0, "R_BT": R_start.reshape(9)})
    # 15 degrees about base x (azimuth 0) at gain 2 is 0.52 rad/s: clamped to 0.1
    np.testing.assert_allclose(out["twist_B"], [0.0, 0.0, 0.0, 0.1, 0.0, 0.0], atol=1e-12)
    assert out["pose_index"][0] == 1.0
    assert out["holding"][0] == 0.0


def test_the_proportional_servo_below_the_limits():
    params = SequencerParams(
        tilts=1, tilt_min_deg=10.0, tilt_max_deg=10.0, directions=4, gain_orientation=1.5
    )
    seq = PoseSequencer(params)
    inputs = {"p_BT_B": P0, "R_BT": R0.reshape(9)}
    seq.step(0.0, DT, inputs)
    # in the second pose's move the target is 10 degrees about base y; from R0 that is the error
    out = seq.step(params.pose_s + 0.5, DT, inputs)
    assert out["pose_index"][0] == 2.0
    np.testing.assert_allclose(
        out["twist_B"], [0.0, 0.0, 0.0, 0.0, 1.5 * math.radians(10.0), 0.0], atol=1e-12
    )
    off = P0 + np.array([0.0, 0.0, 0.01])
    out = seq.step(params.pose_s + 0.6, DT, {"p_BT_B": off, "R_BT": R0.reshape(9)})
    np.testing.assert_allclose(out["twist_B"][:3], [0.0, 0.0, -3.0 * 0.01], atol=1e-12)


def test_the_start_pose_is_taken_at_the_first_step_and_again_after_reset():
    params = SequencerParams(
        tilts=1, tilt_min_deg=10.0, tilt_max_deg=10.0, directions=4, gain_orientation=1.5
    )
    seq = PoseSequencer(params)
    seq.step(0.0, DT, {"p_BT_B": P0, "R_BT": R0.reshape(9)})
    # later steps servo back to the first step's position, wherever the input is now
    moved = P0 + np.array([0.001, 0.0, 0.0])
    out = seq.step(DT, DT, {"p_BT_B": moved, "R_BT": R0.reshape(9)})
    np.testing.assert_allclose(out["twist_B"][:3], [-3.0 * 0.001, 0.0, 0.0], atol=1e-12)
    # after a reset the next step's pose is the new start, and the targets tilt from it
    R_new = rotvec_to_matrix([0.2, 0.1, -0.4])
    seq.reset()
    for k in (2, 3):
        out = seq.step(k * DT, DT, {"p_BT_B": moved, "R_BT": R_new.reshape(9)})
        assert out["pose_index"][0] == 1.0
        assert out["done"][0] == 0.0
        np.testing.assert_allclose(
            out["twist_B"], [0.0, 0.0, 0.0, 1.5 * math.radians(10.0), 0.0, 0.0], atol=1e-12
        )


def test_the_start_is_a_copy_of_the_callers_arrays():
    # the caller refills its input arrays in place every step (the block contract)
    seq = PoseSequencer(
        SequencerParams(
            tilts=1, tilt_min_deg=10.0, tilt_max_deg=10.0, directions=4, max_angular_speed=5.0
        )
    )
    p_in, R_in = P0.copy(), R0.reshape(9).copy()
    inputs = {"p_BT_B": p_in, "R_BT": R_in}
    seq.step(0.0, DT, inputs)
    p_in[:] = P0 + np.array([0.0, 0.002, 0.0])
    R_in[:] = (rotvec_to_matrix([0.0, 0.0, 0.1]) @ R0).reshape(9)
    out = seq.step(DT, DT, inputs)
    np.testing.assert_allclose(out["twist_B"][:3], [0.0, -3.0 * 0.002, 0.0], atol=1e-12)
    # the orientation error is to the target tilted from R0, not from the refilled R
    target = expected_target(R0, 10.0, 0, 4)
    error = matrix_to_rotvec(target @ R_in.reshape(3, 3).T)
    np.testing.assert_allclose(out["twist_B"][3:], 3.0 * error, atol=1e-12)


# --- parameters -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"tilts": 0}, r"tilts must be an integer >= 1, got 0"),
        ({"tilts": True}, r"tilts must be an integer >= 1, got True"),
        ({"tilt_min_deg": -5.0}, r"tilt_min_deg must be >= 0"),
        ({"tilt_max_deg": 130.0}, r"tilt_max_deg must be <= 120"),
        ({"tilt_min_deg": "steep"}, r"tilt_min_deg: expected a number"),
        ({"tilt_min_deg": 50.0, "tilt_max_deg": 40.0}, r"tilt_min_deg must be <= tilt_max_deg"),
        ({"directions": True}, r"directions must be an integer >= 1, got True"),
        ({"directions": 0}, r"directions must be an integer >= 1, got 0"),
        ({"directions": 2.0}, r"directions must be an integer >= 1, got 2\.0"),
        ({"hold_s": -1.0}, r"hold_s must be > 0"),
        ({"hold_s": 0.0}, r"hold_s must be > 0"),
        ({"move_s": 0.0}, r"move_s must be > 0"),
        ({"settle_s": -0.1}, r"settle_s must be >= 0"),
        ({"gain_orientation": -1.0}, r"gain_orientation must be > 0"),
        ({"max_linear_speed": 0.0}, r"max_linear_speed must be > 0"),
        ({"max_angular_speed": float("inf")}, r"max_angular_speed: expected a finite number"),
    ],
)
def test_invalid_parameters_are_refused(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        SequencerParams(**kwargs)


def test_valid_parameters_are_normalised():
    params = SequencerParams(
        tilts=2, tilt_min_deg=10, tilt_max_deg=20, directions=3, settle_s=0, hold_s=1
    )
    assert params.tilts_deg == (10.0, 20.0)
    assert isinstance(params.tilts_deg, tuple)
    assert all(type(x) is float for x in params.tilts_deg)
    assert type(params.hold_s) is float
    assert params.settle_s == 0.0
    assert params.n_poses == 6
    assert params.pose_s == 3.0 + 0.0 + 1.0
