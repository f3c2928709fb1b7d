"""The supervisor: the stop flags of a tick, the limits' order, and every cause that ends a session."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hoh_cosim.control.supervisor import (
    STARVED_TEXT,
    LimitParams,
    SessionPolicy,
    Status,
    check_inputs,
    limit_command,
    robot_cause,
    starved_cause,
    supervise,
)
from tests.estimates import controller_inputs

ROBOT = "UR5 at 192.168.0.10"
FT = "FT-150 at 192.168.1.1"
PROBE = "FSE103 on /dev/ttyUSB0"
POLICY = SessionPolicy(LimitParams(), robot=ROBOT, ft=FT, probe=PROBE)
NO_PROBE = SessionPolicy(LimitParams(), robot=ROBOT, ft=FT)

MOVING = np.array([0.03, -0.02, 0.01, 0.0, 0.1, -0.05])  # a twist inside every limit
HELD = np.zeros(6)  # what the controller commands on a stop flag


estimate = controller_inputs


def verdict_of(status, twist=MOVING, policy=POLICY, *, ft=None, probe=None, **kwargs):
    if ft is None:
        ft = np.zeros(6)
    if probe is None and policy.probe is not None:
        probe = np.zeros(3)
    est = estimate(**kwargs.pop("estimate", {}))
    return supervise(policy, Status(status), est, twist, ft=ft, probe=probe, **kwargs)


def assert_stopped(verdict, cause):
    assert verdict.cause == cause
    np.testing.assert_array_equal(verdict.twist_B, np.zeros(6))


# --- supervise: one test per cause --------------------------------------------------------------


@pytest.mark.parametrize(
    ("problem", "cause"),
    [
        ("protective stop", f"{ROBOT}: protective stop"),
        ("emergency stop", f"{ROBOT}: emergency stop"),
        ("program not running", f"{ROBOT}: program not running"),
    ],
)
def test_robot_cause_names_the_robot_from_the_policy(problem, cause):
    assert robot_cause(POLICY, problem) == cause


def test_robot_cause_defaults_to_the_robot():
    assert robot_cause(SessionPolicy(LimitParams()), "protective stop") == (
        "the robot: protective stop"
    )


@pytest.mark.parametrize(
    ("ft", "cause"),
    [
        (
            [1.23456, np.nan, 0.0, 0.0, -2.0004, 0.1],
            f"{FT} sent a non-finite value [1.235, nan, 0.0, 0.0, -2.0, 0.1]",
        ),
        (
            [0.5, 0.25, -0.125, np.inf, 0.0, 0.0],
            f"{FT} sent a non-finite value [0.5, 0.25, -0.125, inf, 0.0, 0.0]",
        ),
        (
            [0.0, 0.0, -np.inf, 0.0, 0.0, 0.0009],
            f"{FT} sent a non-finite value [0.0, 0.0, -inf, 0.0, 0.0, 0.001]",
        ),
    ],
)
@pytest.mark.parametrize("status", [Status(0), Status.SPEED_CLAMPED, Status.FORCE_STOP])
def test_a_non_finite_ft150_sample_ends_the_session(ft, cause, status):
    # the raw sample is checked first: the estimator rejects it, so nothing else would show it
    verdict = verdict_of(status, ft=np.array(ft), estimate={"F_probe_B": [0.0, 0.0, 26.0]})
    assert_stopped(verdict, cause)
    assert verdict.status == status


@pytest.mark.parametrize(
    ("probe", "cause"),
    [
        ([np.nan, 1.0, 2.0], f"{PROBE} sent a non-finite value [nan, 1.0, 2.0]"),
        ([0.12345, -np.inf, 7.77777], f"{PROBE} sent a non-finite value [0.123, -inf, 7.778]"),
    ],
)
def test_a_non_finite_probe_sample_ends_the_session(probe, cause):
    assert_stopped(verdict_of(Status(0), probe=np.array(probe)), cause)


def test_the_ft150_sample_is_named_before_the_probe_sample():
    verdict = verdict_of(Status(0), ft=np.full(6, np.nan), probe=np.array([np.nan, 0.0, 0.0]))
    assert_stopped(verdict, f"{FT} sent a non-finite value [nan, nan, nan, nan, nan, nan]")


def test_no_sample_yet_is_not_a_fault():
    verdict = supervise(POLICY, Status(0), estimate(), MOVING, ft=None, probe=None)
    assert verdict.cause is None
    assert verdict.twist_B is MOVING


@pytest.mark.parametrize(
    ("F_probe_B", "limits", "cause"),
    [
        ([0.0, 0.0, 25.0], LimitParams(), "probe contact force 25.0 N reached the 25 N stop"),
        ([3.0, 4.0, 25.04], LimitParams(), "probe contact force 25.5 N reached the 25 N stop"),
        (
            [-12.0, 0.0, 16.0],
            LimitParams(probe_force_soft_cap=15.0, probe_force_stop=18.5),
            "probe contact force 20.0 N reached the 18.5 N stop",
        ),
    ],
)
def test_the_probe_force_stop_ends_the_session(F_probe_B, limits, cause):
    policy = SessionPolicy(limits, robot=ROBOT, ft=FT, probe=PROBE)
    verdict = verdict_of(Status.FORCE_STOP, policy=policy, estimate={"F_probe_B": F_probe_B})
    assert_stopped(verdict, cause)
    assert verdict.status == Status.FORCE_STOP


@pytest.mark.parametrize(
    ("flag", "age_port"), [(Status.STALE_FT, "ft_age"), (Status.STALE_PROBE, "probe_age")]
)
@pytest.mark.parametrize("age", [0.016, 0.1, 0.249999])
def test_a_short_gap_passes_the_controllers_zero(flag, age_port, age):
    verdict = verdict_of(flag, HELD, estimate={age_port: age}, ft_error="socket timed out")
    assert verdict.cause is None
    assert verdict.twist_B is HELD
    assert verdict.status == flag


@pytest.mark.parametrize(
    ("age", "error", "cause"),
    [
        (0.25, "socket timed out", f"{FT}: no new sample for 250 ms (socket timed out)"),
        (0.4321, "socket timed out", f"{FT}: no new sample for 432 ms (socket timed out)"),
        (0.25, None, f"{FT}: no new sample for 250 ms (the stream stalled)"),
        (3.0, None, f"{FT}: no new sample for 3000 ms (the stream stalled)"),
    ],
)
def test_a_stale_ft150_stream_ends_the_session_after_stale_stop_s(age, error, cause):
    verdict = verdict_of(
        Status.STALE_FT,
        HELD,
        estimate={"ft_age": age},
        ft_error=error,
        probe_error="should not be named",
    )
    assert_stopped(verdict, cause)
    assert verdict.status == Status.STALE_FT


@pytest.mark.parametrize(
    ("age", "error", "cause"),
    [
        (0.25, "read timed out", f"{PROBE}: no new sample for 250 ms (read timed out)"),
        (0.5004, "read timed out", f"{PROBE}: no new sample for 500 ms (read timed out)"),
        (0.25, None, f"{PROBE}: no new sample for 250 ms (the stream stalled)"),
    ],
)
def test_a_stale_probe_stream_ends_the_session_after_stale_stop_s(age, error, cause):
    verdict = verdict_of(
        Status.STALE_PROBE,
        HELD,
        estimate={"probe_age": age},
        ft_error="should not be named",
        probe_error=error,
    )
    assert_stopped(verdict, cause)


@pytest.mark.parametrize(("stale_stop_s", "ends"), [(0.1, True), (0.5, False)])
def test_stale_stop_s_is_the_policys(stale_stop_s, ends):
    policy = SessionPolicy(LimitParams(), stale_stop_s=stale_stop_s, ft=FT, probe=PROBE)
    verdict = verdict_of(Status.STALE_FT, HELD, policy=policy, estimate={"ft_age": 0.2})
    assert verdict.cause == (
        f"{FT}: no new sample for 200 ms (the stream stalled)" if ends else None
    )


def test_a_long_probe_silence_ends_the_session_during_a_short_ft150_gap():
    # each stream gets `stale_stop_s`: a short FT-150 gap must not hide a probe silent for longer
    verdict = verdict_of(
        Status.STALE_FT | Status.STALE_PROBE,
        HELD,
        estimate={"ft_age": 0.02, "probe_age": 0.3},
        probe_error="read timed out",
    )
    assert_stopped(verdict, f"{PROBE}: no new sample for 300 ms (read timed out)")


def test_a_silence_on_an_overloaded_machine_is_named_so():
    overload = "this machine was overloaded: tasks waited for a CPU 80 % of the last 190 ms"
    verdict = verdict_of(Status.STALE_PROBE, HELD, estimate={"probe_age": 0.25}, overload=overload)
    assert_stopped(
        verdict,
        f"{PROBE}: no new sample for 250 ms ({overload}: its delivery was starved, not "
        "necessarily the device)",
    )


def test_a_readers_own_error_comes_before_the_machines_load():
    verdict = verdict_of(
        Status.STALE_FT, HELD, estimate={"ft_age": 0.3}, ft_error="connection lost", overload="x"
    )
    assert_stopped(verdict, f"{FT}: no new sample for 300 ms (connection lost)")


def test_the_machines_load_alone_ends_nothing():
    # the load only names a silence that ends the session anyway
    verdict = verdict_of(Status.STALE_FT, HELD, estimate={"ft_age": 0.1}, overload="x")
    assert verdict.cause is None


@pytest.mark.parametrize(
    ("flag", "age_port", "device"),
    [(Status.STALE_FT, "ft_age", FT), (Status.STALE_PROBE, "probe_age", PROBE)],
)
def test_silence_while_ordinary_tasks_were_starved_is_not_counted(flag, age_port, device):
    # 300 ms silent, 100 ms of it starved: 200 ms counted, the command stays zero
    verdict = verdict_of(flag, HELD, estimate={age_port: 0.3}, starved={flag: 0.1})
    assert verdict.cause is None
    assert verdict.status == flag
    # 400 ms silent, 100 ms of it starved: 300 ms counted, past the 250 ms limit
    verdict = verdict_of(flag, HELD, estimate={age_port: 0.4}, starved={flag: 0.1})
    assert_stopped(
        verdict,
        f"{device}: no new sample for 400 ms (the stream stalled; 100 {STARVED_TEXT})",
    )


def test_a_stale_streams_stop_says_what_its_reader_got_since_its_last_sample():
    quiet = {
        Status.STALE_PROBE: "60 bytes read since its last sample, the last 3 ms ago, 2 bad frames",
        Status.STALE_FT: "no byte read since its last sample",
    }
    verdict = verdict_of(
        Status.STALE_PROBE, HELD, estimate={"probe_age": 0.4}, starved={}, quiet=quiet
    )
    assert_stopped(
        verdict,
        f"{PROBE}: no new sample for 400 ms (the stream stalled: 60 bytes read since its last "
        "sample, the last 3 ms ago, 2 bad frames)",
    )
    # before the starved time, which the campaign's checker reads at the end
    verdict = verdict_of(
        Status.STALE_FT, HELD, estimate={"ft_age": 0.4}, starved={Status.STALE_FT: 0.1}, quiet=quiet
    )
    assert_stopped(
        verdict,
        f"{FT}: no new sample for 400 ms (the stream stalled: no byte read since its last sample; "
        f"100 {STARVED_TEXT})",
    )
    # a reader that said why needs no byte count
    verdict = verdict_of(
        Status.STALE_FT, HELD, estimate={"ft_age": 0.4}, quiet=quiet, ft_error="socket timed out"
    )
    assert_stopped(verdict, f"{FT}: no new sample for 400 ms (socket timed out)")


def test_a_starved_machine_defers_a_stop_only_up_to_stale_stop_max_s():
    policy = SessionPolicy(LimitParams(), stale_stop_max_s=0.8, ft=FT, probe=PROBE)
    starved = {Status.STALE_PROBE: 10.0}  # starved all along (and then some: clipped to the age)
    verdict = verdict_of(
        Status.STALE_PROBE, HELD, policy=policy, estimate={"probe_age": 0.79}, starved=starved
    )
    assert verdict.cause is None
    verdict = verdict_of(
        Status.STALE_PROBE, HELD, policy=policy, estimate={"probe_age": 0.8}, starved=starved
    )
    assert_stopped(
        verdict, f"{PROBE}: no new sample for 800 ms (the stream stalled; 800 {STARVED_TEXT})"
    )


def test_one_streams_starved_time_does_not_defer_the_others_stop():
    verdict = verdict_of(
        Status.STALE_FT | Status.STALE_PROBE,
        HELD,
        estimate={"ft_age": 0.26, "probe_age": 0.26},
        starved={Status.STALE_PROBE: 0.2},
    )
    assert_stopped(verdict, f"{FT}: no new sample for 260 ms (the stream stalled)")


@pytest.mark.parametrize(
    ("silent_s", "cause"),
    [
        (0.0, None),
        (0.049, None),
        (
            0.05,
            "the control loop was starved: no command for 50 ms before cycle 7, past the "
            "robot's 50 ms watchdog (this machine is overloaded, or the loop lacks its real-time "
            "priority)",
        ),
    ],
)
def test_a_silence_as_long_as_the_watchdog_is_a_starved_loop(silent_s, cause):
    policy = SessionPolicy(LimitParams(), watchdog_s=0.05)
    assert starved_cause(policy, "cycle 7", silent_s) == cause


def test_without_a_watchdog_no_silence_ends_a_session():
    assert starved_cause(POLICY, "cycle 1", 10.0) is None
    assert starved_cause(POLICY, "cycle 1", math.inf) is None


def test_a_stale_probe_flag_without_a_probe_stops_the_controller():
    verdict = verdict_of(Status.STALE_PROBE, policy=NO_PROBE, estimate={"probe_age": 0.01})
    assert_stopped(verdict, "the controller stopped: stale probe-sensor data")


def test_not_ready_outside_the_probe_check_ends_the_session():
    verdict = verdict_of(Status.NOT_READY, HELD)
    assert_stopped(verdict, "the controller stopped: estimator not ready (rebiasing)")
    assert verdict.status == Status.NOT_READY


@pytest.mark.parametrize("extra", [Status(0), Status.FIXTURE])
def test_not_ready_during_the_probe_check_is_masked(extra):
    verdict = verdict_of(Status.NOT_READY | extra, HELD, checking=True)
    assert verdict.cause is None
    assert verdict.twist_B is HELD
    assert verdict.status == extra
    assert not verdict.status & Status.NOT_READY


def test_the_probe_check_masks_not_ready_only():
    verdict = verdict_of(
        Status.NOT_READY | Status.STALE_FT, HELD, checking=True, estimate={"ft_age": 0.3}
    )
    assert_stopped(verdict, f"{FT}: no new sample for 300 ms (the stream stalled)")
    assert verdict.status == Status.STALE_FT


@pytest.mark.parametrize(
    ("status", "cause"),
    [
        (Status.NONFINITE, "the controller stopped: non-finite input (latched)"),
        (
            Status.NONFINITE | Status.NOT_READY,
            "the controller stopped: non-finite input (latched), estimator not ready (rebiasing)",
        ),
    ],
)
def test_the_latched_non_finite_flag_ends_the_session(status, cause):
    assert_stopped(verdict_of(status), cause)


@pytest.mark.parametrize(
    ("twist", "cause"),
    [
        ([np.nan, 0.0, 0.0, 0.0, 0.0, 0.0], "non-finite command [nan, 0.0, 0.0, 0.0, 0.0, 0.0]"),
        ([0.01, 0.0, 0.0, 0.0, 0.0, np.inf], "non-finite command [0.01, 0.0, 0.0, 0.0, 0.0, inf]"),
    ],
)
def test_a_non_finite_command_ends_the_session(twist, cause):
    assert_stopped(verdict_of(Status(0), np.array(twist)), cause)


@pytest.mark.parametrize(
    ("twist", "cause"),
    [
        (
            [0.2, 0.0, 0.0, 0.0, 0.0, 0.0],
            "command above the speed limits: 0.2000 m/s, 0.0000 rad/s",
        ),
        (
            [0.0, 0.06, 0.0801, 0.0, 0.0, 0.1],
            "command above the speed limits: 0.1001 m/s, 0.1000 rad/s",
        ),
        (
            [0.0, 0.0, 0.0, 0.0, 0.6, 0.8],
            "command above the speed limits: 0.0000 m/s, 1.0000 rad/s",
        ),
        (
            [0.01, 0.0, 0.0, 0.3, 0.0, -0.4001],
            "command above the speed limits: 0.0100 m/s, 0.5001 rad/s",
        ),
    ],
)
def test_a_command_above_a_speed_limit_ends_the_session(twist, cause):
    assert_stopped(verdict_of(Status(0), np.array(twist)), cause)


def test_a_command_at_the_speed_limits_passes():
    twist = np.array([0.06, 0.0, -0.08, 0.3, 0.4, 0.0])  # 0.1 m/s and 0.5 rad/s
    verdict = verdict_of(Status.SPEED_CLAMPED, twist)
    assert verdict.cause is None
    assert verdict.twist_B is twist
    assert verdict.status == Status.SPEED_CLAMPED


@pytest.mark.parametrize(
    "status",
    [
        Status(0),
        Status.SPEED_CLAMPED | Status.ACCEL_CLAMPED,
        Status.WORKSPACE | Status.FORCE_SOFT_CAP | Status.FIXTURE,
    ],
)
def test_a_clean_cycle_sends_the_command(status, rng):
    twist = rng.uniform(-0.05, 0.05, 6)
    verdict = verdict_of(status, twist)
    assert verdict.cause is None
    assert verdict.twist_B is twist
    assert verdict.status == status


# --- check_inputs: the stop flags of one tick ---------------------------------------------------


def flags(use_probe=True, limits=None, ft_period_s=0.005, probe_period_s=0.02, **overrides):
    return check_inputs(
        estimate(**overrides),
        limits or LimitParams(),
        ft_period_s=ft_period_s,
        probe_period_s=probe_period_s,
        use_probe=use_probe,
    )


def test_a_fresh_ready_estimate_has_no_flags():
    assert flags() == 0
    assert flags(F_hand_B=[30.0, -4.0, 2.0], F_probe_B=[0.0, 0.0, 24.9]) == 0


@pytest.mark.parametrize(
    ("port", "value"),
    [
        ("F_hand_B", [np.nan, 0.0, 0.0]),
        ("tau_hand_B", [0.0, np.inf, 0.0]),
        ("F_probe_B", [0.0, 0.0, -np.inf]),
        ("p_BT_B", [0.3, np.nan, 0.3]),
        ("ft_age", np.nan),
        ("probe_age", np.inf),
        ("ready", np.nan),
    ],
)
@pytest.mark.parametrize("use_probe", [True, False])
def test_a_non_finite_input_is_the_only_flag(port, value, use_probe):
    # stale, unready and over the force stop as well: non-finite says it all
    worst = {"ft_age": 1.0, "probe_age": 1.0, "ready": 0.0, "F_probe_B": [0.0, 0.0, 30.0]}
    assert flags(use_probe, **(worst | {port: value})) == int(Status.NONFINITE)


# numpy warns of the overflow it sees; the check must still call it a fault
@pytest.mark.filterwarnings("ignore:overflow encountered in matmul:RuntimeWarning")
@pytest.mark.parametrize("port", ["F_hand_B", "tau_hand_B", "F_probe_B", "p_BT_B"])
def test_an_overflowing_input_is_non_finite(port):
    assert flags(**{port: [1e200, 0.0, 0.0]}) == int(Status.NONFINITE)


@pytest.mark.parametrize("ready", [0.0, 0.49])
def test_not_ready_below_one_half(ready):
    assert flags(ready=ready) == int(Status.NOT_READY)


def test_ready_from_one_half():
    assert flags(ready=0.5) == 0


@pytest.mark.parametrize(
    ("stale_periods", "period"), [(3.0, 0.005), (3.0, 0.016), (2.5, 0.01), (4.0, 0.008)]
)
@pytest.mark.parametrize("use_probe", [True, False])
def test_stale_ft_after_stale_periods_periods(stale_periods, period, use_probe):
    limits = LimitParams(stale_periods=stale_periods)
    at = stale_periods * period
    assert flags(use_probe, limits, ft_period_s=period, ft_age=at) == 0
    past = np.nextafter(at, np.inf)
    assert flags(use_probe, limits, ft_period_s=period, ft_age=past) == int(Status.STALE_FT)


@pytest.mark.parametrize(("stale_periods", "period"), [(3.0, 0.02), (3.0, 0.01), (2.5, 0.004)])
def test_stale_probe_after_stale_periods_periods(stale_periods, period):
    limits = LimitParams(stale_periods=stale_periods)
    at = stale_periods * period
    assert flags(limits=limits, probe_period_s=period, probe_age=at) == 0
    past = np.nextafter(at, np.inf)
    assert flags(limits=limits, probe_period_s=period, probe_age=past) == int(Status.STALE_PROBE)


@pytest.mark.parametrize(
    ("F_probe_B", "limits"),
    [
        ([0.0, 0.0, 25.0], LimitParams()),
        ([15.0, -20.0, 0.0], LimitParams()),
        ([0.0, 18.0, 0.0], LimitParams(probe_force_soft_cap=10.0, probe_force_stop=18.0)),
    ],
)
def test_force_stop_at_the_limit(F_probe_B, limits):
    assert flags(limits=limits, F_probe_B=F_probe_B) == int(Status.FORCE_STOP)
    below = np.nextafter(np.asarray(F_probe_B), 0.0)
    assert flags(limits=limits, F_probe_B=below) == 0


def test_every_stop_flag_at_once():
    out = flags(ft_age=0.02, probe_age=0.1, ready=0.0, F_probe_B=[0.0, 0.0, 26.0])
    assert out == int(Status.NOT_READY | Status.STALE_FT | Status.STALE_PROBE | Status.FORCE_STOP)


def test_no_probe_checks_without_a_probe():
    assert flags(False, probe_age=100.0, F_probe_B=[0.0, 0.0, 30.0]) == 0
    assert flags(False, ft_age=0.02, probe_age=100.0) == int(Status.STALE_FT)
    assert flags(False, ready=0.0, F_probe_B=[0.0, 0.0, 30.0]) == int(Status.NOT_READY)


# --- limit_command: speed, acceleration, soft cap, workspace, in that order -----------------------

LIMITS = LimitParams(workspace_min_B=[-0.5, -0.5, 0.1], workspace_max_B=[0.5, 0.5, 0.6])
BOX = (LIMITS.workspace_min_B.tolist(), LIMITS.workspace_max_B.tolist())
DT = 2e-3
INSIDE = np.array([0.2, 0.0, 0.3])
ZERO = np.zeros(3)


def limited(v, w, v_prev=ZERO, w_prev=ZERO, F_probe_B=ZERO, p_BT_B=INSIDE):
    def arr(x):
        return None if x is None else np.asarray(x, dtype=float)

    return limit_command(
        arr(v), arr(w), arr(v_prev), arr(w_prev), DT, arr(F_probe_B), arr(p_BT_B), LIMITS, BOX
    )


def test_a_command_inside_every_limit_passes(rng):
    v, w = rng.uniform(-0.05, 0.05, 3), rng.uniform(-0.2, 0.2, 3)
    v_prev, w_prev = v + rng.uniform(-5e-4, 5e-4, 3), w + rng.uniform(-2e-3, 2e-3, 3)
    v_out, w_out, status = limited(v, w, v_prev, w_prev)
    np.testing.assert_array_equal(v_out, v)
    np.testing.assert_array_equal(w_out, w)
    assert status == 0


def test_speed_is_clamped_before_the_acceleration():
    # from 0.099 m/s toward 1 m/s: clamped to 0.1 first, a step of 1 mm/s is within 2 mm/s per tick
    v_out, _, status = limited([1.0, 0.0, 0.0], ZERO, v_prev=[0.099, 0.0, 0.0])
    np.testing.assert_allclose(v_out, [0.1, 0.0, 0.0], rtol=0, atol=1e-15)
    assert status == int(Status.SPEED_CLAMPED)


def test_angular_speed_and_acceleration_are_clamped_too():
    v_out, w_out, status = limited(ZERO, [0.0, 0.0, 3.0], w_prev=[0.0, 0.0, 0.45])
    np.testing.assert_allclose(w_out, [0.0, 0.0, 0.45 + 5.0 * DT], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(v_out, ZERO)
    assert status == int(Status.SPEED_CLAMPED | Status.ACCEL_CLAMPED)


def test_the_workspace_face_overrides_the_acceleration_clamp():
    # moving out through the +x face at 0.05 m/s, the law says stop: the ramp-down would keep
    # 0.048 m/s outward, the face allows none
    at_face = [0.5, 0.0, 0.3]
    v_out, _, status = limited(ZERO, ZERO, v_prev=[0.05, 0.01, 0.0], p_BT_B=at_face)
    assert v_out[0] == 0.0
    assert v_out[1] > 0.0  # along the face stays free (and ramps down)
    assert status == int(Status.ACCEL_CLAMPED | Status.WORKSPACE)


def test_the_workspace_face_overrides_a_ramp_up():
    v_out, _, status = limited([0.1, 0.0, 0.0], ZERO, v_prev=[0.05, 0.0, 0.0], p_BT_B=[0.5, 0, 0.3])
    np.testing.assert_array_equal(v_out, ZERO)
    assert status == int(Status.ACCEL_CLAMPED | Status.WORKSPACE)


def test_the_soft_cap_overrides_the_acceleration_clamp():
    # pressing down at 0.05 m/s into 21 N: the ramp-down would keep 0.048 m/s into the patient
    v_out, _, status = limited(ZERO, ZERO, v_prev=[0.0, 0.0, -0.05], F_probe_B=[0.0, 0.0, 21.0])
    np.testing.assert_array_equal(v_out, ZERO)
    assert status == int(Status.ACCEL_CLAMPED | Status.FORCE_SOFT_CAP)


def test_the_soft_cap_is_skipped_without_a_probe():
    v = [0.02, 0.0, -0.05]
    v_out, _, status = limited(v, ZERO, v_prev=v, F_probe_B=None)
    np.testing.assert_array_equal(v_out, v)
    assert status == 0
    v_out, _, status = limited(v, ZERO, v_prev=v, F_probe_B=[0.0, 0.0, 21.0])
    np.testing.assert_array_equal(v_out, [0.02, 0.0, 0.0])
    assert status == int(Status.FORCE_SOFT_CAP)


def test_the_workspace_comes_after_the_soft_cap():
    # the cap removes the downward part, the floor then has nothing left to remove
    on_floor = [0.2, 0.0, 0.1]
    v_out, _, status = limited(
        [0.0, 0.0, -0.05],
        ZERO,
        v_prev=[0.0, 0.0, -0.05],
        F_probe_B=[0.0, 0.0, 21.0],
        p_BT_B=on_floor,
    )
    np.testing.assert_array_equal(v_out, ZERO)
    assert status == int(Status.FORCE_SOFT_CAP)
