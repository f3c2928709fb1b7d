"""One control cycle: the rig's sensors given to both blocks, the blocks stepped as by hand, the
supervisor's verdict and the session's events."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from hoh_cosim.control.controller import ControllerParams, HandGuidingController
from hoh_cosim.control.cycle import (
    FOLLOW_GAP_S,
    ControlBlocks,
    Event,
    Reading,
    SensorSetup,
    control_cycle,
)
from hoh_cosim.control.estimator import Estimator, EstimatorParams
from hoh_cosim.control.follow import FollowParams
from hoh_cosim.control.frames import R_BS_EQ1, R_SP_SEED, rotvec_to_matrix
from hoh_cosim.control.gravity import SEED_TOOL, tool_weight_wrench_S
from hoh_cosim.control.probe_correction import ProbeCorrectionParams
from hoh_cosim.control.supervisor import LimitParams, SessionPolicy, Status, supervise
from hoh_cosim.errors import ConfigError
from hoh_cosim.params import leaves

DT = 2e-3  # a 500 Hz robot
FT_EVERY, PROBE_EVERY = 2, 10  # FT-150 every 4 ms, FSE103 every 20 ms
FT_BIAS = np.array([1.0, -2.0, 0.5, 0.02, -0.01, 0.03])
PROBE_BIAS = np.array([0.3, 0.1, -0.2])
P_BT_B = np.array([0.4, 0.0, 0.3])
SENSOR_FIELDS = {
    "estimator": {"ft_packet_period_s", "probe_packet_period_s", "use_probe"},
    "controller": {"ft_period_s", "probe_period_s", "use_probe"},
}


def exactly(message: str) -> str:
    return f"^{re.escape(message)}$"


# --- SensorSetup -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "setup",
    [
        SensorSetup(ft_period_s=0.008, probe_period_s=0.0125, use_probe=True),
        SensorSetup(ft_period_s=0.016, probe_period_s=0.04, use_probe=False),
        SensorSetup(ft_period_s=0.01, probe_period_s=0.02, use_probe=True),
    ],
)
def test_apply_sets_the_sensors_in_both_blocks_and_nothing_else(setup):
    estimator = EstimatorParams(filter="one_euro", ft_rebias_packets=50, probe_mass_kg=0.05)
    controller = ControllerParams(
        virtual_fixture=True, limits=LimitParams(max_linear_speed=0.08, stale_periods=4.0)
    )
    new_estimator, new_controller = setup.apply(estimator, controller)

    assert new_estimator.ft_packet_period_s == setup.ft_period_s
    assert new_estimator.probe_packet_period_s == setup.probe_period_s
    assert new_estimator.use_probe is setup.use_probe
    assert new_controller.ft_period_s == setup.ft_period_s
    assert new_controller.probe_period_s == setup.probe_period_s
    assert new_controller.use_probe is setup.use_probe
    assert SensorSetup.of(new_estimator) == setup

    for block, old, new in (
        ("estimator", estimator, new_estimator),
        ("controller", controller, new_controller),
    ):
        before = {leaf.name: leaf for leaf in leaves(old)}
        after = {leaf.name: leaf for leaf in leaves(new)}
        assert list(after) == list(before)
        unchanged = [name for name in before if name not in SENSOR_FIELDS[block]]
        assert [after[name] for name in unchanged] == [before[name] for name in unchanged]
    # the originals are left as they were
    assert estimator.ft_packet_period_s == 0.005
    assert controller.ft_period_s == 0.005


def test_of_reads_the_estimators_sensors():
    params = EstimatorParams(ft_packet_period_s=0.01, probe_packet_period_s=0.025, use_probe=False)
    assert SensorSetup.of(params) == SensorSetup(0.01, 0.025, False)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"ft_period_s": 0.0}, "ft_period_s must be > 0.0, got 0.0"),
        ({"ft_period_s": -0.005}, "ft_period_s must be > 0.0, got -0.005"),
        ({"probe_period_s": 0.0}, "probe_period_s must be > 0.0, got 0.0"),
        ({"probe_period_s": -0.02}, "probe_period_s must be > 0.0, got -0.02"),
        ({"ft_period_s": math.nan}, "ft_period_s: expected a finite number, got nan"),
        ({"probe_period_s": "fast"}, "probe_period_s: expected a number, got 'fast'"),
    ],
)
def test_sensor_setup_rejects_a_non_positive_period(kwargs, message):
    with pytest.raises(ConfigError, match=exactly(message)):
        SensorSetup(**kwargs)


def test_shared_refuses_a_controller_that_contradicts_the_estimator():
    estimator = EstimatorParams(ft_packet_period_s=0.008)
    with pytest.raises(
        ConfigError,
        match=exactly(
            "controller.ft_period_s: 0.01 contradicts estimator.ft_packet_period_s: 0.008 "
            "(the sensors are given once, in the estimator's parameters)"
        ),
    ):
        SensorSetup.shared(estimator, ControllerParams(ft_period_s=0.01))
    # a controller left at its default takes the estimator's
    assert SensorSetup.shared(estimator, ControllerParams()) == SensorSetup(0.008, 0.02, True)


# --- control_cycle ------------------------------------------------------------------------------


def wrist_turn(k: int) -> np.ndarray:
    """R_BS at cycle k of `session`: the wrist turning slowly about the calibration's pose."""
    t = k * DT
    return R_BS_EQ1 @ rotvec_to_matrix(0.2 * np.sin([0.7 * t, 1.1 * t, 0.5 * t]))


def session(
    n: int,
    rng: np.random.Generator,
    *,
    first_ft: int = 0,
    ft_gap: range = range(0),
    hand_from: int = 0,
    contact_B=lambda k: np.zeros(3),
    probe_only_P=lambda k: np.zeros(3),
) -> list[Reading]:
    """The readings of `n` cycles: the wrist turning slowly, a seeded hand pushing from
    `hand_from` on, the contact force on both sensors, noise on both, no FT-150 sample before
    `first_ft` or during `ft_gap`; `probe_only_P` is read by the probe sensor alone."""
    phase = rng.uniform(0.0, 2.0 * np.pi, 6)
    amplitude = np.array([6.0, 5.0, 4.0, 0.4, 0.3, 0.5])
    ft = probe = None
    ft_count = probe_count = 0
    out = []
    for k in range(n):
        t = k * DT
        R_BS = wrist_turn(k)
        if k % FT_EVERY == 0 and k >= first_ft and k not in ft_gap:
            push = amplitude * np.sin(2.0 * np.pi * 0.8 * t + phase) if k >= hand_from else 0
            push = push + np.concatenate([contact_B(k), np.zeros(3)])
            external_S = np.concatenate([R_BS.T @ push[:3], R_BS.T @ push[3:]])
            noise = rng.normal(0.0, 1.0, 6) * np.array([0.3, 0.3, 0.1, 0.01, 0.01, 0.01])
            ft = tool_weight_wrench_S(R_BS, SEED_TOOL) + FT_BIAS + external_S + noise
            ft_count += 1
        if k % PROBE_EVERY == 0:
            R_BP = R_BS @ R_SP_SEED
            probe = R_BP.T @ contact_B(k) + probe_only_P(k) + PROBE_BIAS
            probe = probe + rng.normal(0.0, 0.05, 3)
            probe_count += 1
        p_BT_B = P_BT_B + 0.01 * np.array([np.sin(t), np.cos(t), 0.0])
        out.append(Reading(p_BT_B, R_BS, ft, ft_count, probe, probe_count))
    return out


def blocks_for(
    estimator: EstimatorParams,
    policy: SessionPolicy | None = None,
    controller: ControllerParams | None = None,
) -> ControlBlocks:
    setup = SensorSetup(FT_EVERY * DT, PROBE_EVERY * DT, estimator.use_probe)
    estimator, controller = setup.apply(estimator, controller or ControllerParams())
    if policy is None:
        policy = SessionPolicy(controller.limits, probe="FSE103" if setup.use_probe else None)
    return ControlBlocks(Estimator(estimator), HandGuidingController(controller), policy)


@pytest.mark.parametrize(
    ("filter_kind", "use_probe"),
    [("kalman", True), ("steady_kalman", True), ("one_euro", False), ("kalman", False)],
)
def test_a_cycle_is_the_two_blocks_stepped_by_hand(filter_kind, use_probe, rng):
    params = EstimatorParams(
        filter=filter_kind, ft_rebias_packets=20, probe_rebias_packets=3, use_probe=use_probe
    )
    blocks = blocks_for(params)
    estimator = Estimator(blocks.estimator.params)
    controller = HandGuidingController(blocks.controller.params)
    readings = session(
        400,
        rng,
        first_ft=3,
        ft_gap=range(250, 280),
        hand_from=60,
        contact_B=lambda k: np.array([0.0, 0.0, 4.0 if 150 <= k < 200 else 0.0]),
    )

    statuses, causes = set(), set()
    moved = 0
    for k, reading in enumerate(readings):
        t = k * DT
        cycle = control_cycle(blocks, reading, t, DT)
        estimate = estimator.step(
            t,
            DT,
            {
                "wrench_S": np.zeros(6) if reading.ft is None else reading.ft,
                "ft_counter": np.array([float(reading.ft_count)]),
                "force_P": np.zeros(3) if reading.probe is None else reading.probe,
                "probe_counter": np.array([float(reading.probe_count)]),
                "R_BS": reading.R_BS.reshape(9),
            },
        )
        command = controller.step(t, DT, {**estimate, "p_BT_B": reading.p_BT_B})

        assert cycle.reading is reading
        assert list(cycle.estimate) == list(estimate)
        for name, value in estimate.items():
            np.testing.assert_array_equal(cycle.estimate[name], value, err_msg=f"{name}, tick {k}")
        assert list(cycle.command) == list(command)
        for name, value in command.items():
            np.testing.assert_array_equal(cycle.command[name], value, err_msg=f"{name}, tick {k}")
        status = Status(int(command["status"][0]))
        assert cycle.status == status
        verdict = supervise(
            blocks.policy, status, estimate, command["twist_B"], ft=reading.ft, probe=reading.probe
        )
        assert cycle.verdict.cause == verdict.cause
        np.testing.assert_array_equal(cycle.verdict.twist_B, verdict.twist_B)
        statuses.add(status)
        causes.add(cycle.verdict.cause)
        moved += bool(np.any(command["twist_B"] != 0.0))

    # the run went through the rebias, guiding and a stale gap
    assert Status.NOT_READY in statuses
    assert Status.STALE_FT in statuses
    assert moved > 200
    # and the verdict: the rebias ends a session, the 60 ms gap does not
    assert causes == {"the controller stopped: estimator not ready (rebiasing)", None}


@pytest.mark.parametrize(
    ("ft", "cause"),
    [
        (
            [1.5, np.nan, -2.25, 0.0, 0.125, 0.0],
            "FT-150 sent a non-finite value [1.5, nan, -2.25, 0.0, 0.125, 0.0]",
        ),
        (
            [0.0, 0.0, 0.0, np.inf, 0.0, -0.0004],
            "FT-150 sent a non-finite value [0.0, 0.0, 0.0, inf, 0.0, -0.0]",
        ),
    ],
)
def test_a_nan_ft150_sample_ends_the_session(ft, cause, rng):
    params = EstimatorParams(
        ft_rebias_packets=0, probe_rebias_packets=0, ft_bias=FT_BIAS, probe_bias=PROBE_BIAS
    )
    blocks = blocks_for(params)
    readings = session(100, rng, hand_from=0)
    for k, reading in enumerate(readings):
        cycle = control_cycle(blocks, reading, k * DT, DT)
        assert cycle.verdict.cause is None
    assert np.any(cycle.verdict.twist_B != 0.0)  # guiding when the bad sample comes

    last = readings[-1]
    bad = Reading(last.p_BT_B, last.R_BS, np.array(ft), last.ft_count + 1, last.probe, 5)
    cycle = control_cycle(blocks, bad, 100 * DT, DT)
    assert cycle.verdict.cause == cause
    np.testing.assert_array_equal(cycle.verdict.twist_B, np.zeros(6))
    # the estimator refused the sample and the controller saw nothing wrong: the supervisor stops
    assert cycle.estimate["rejected_packets"][0] == 1.0
    assert cycle.status.ok


def check_params(kind: str, check_s: float = 0.1, use_probe: bool = True) -> EstimatorParams:
    # as on the robot: the biases measured before the loop, no rebias inside it
    return EstimatorParams(
        ft_rebias_packets=0,
        probe_rebias_packets=0,
        ft_bias=FT_BIAS,
        probe_bias=PROBE_BIAS,
        use_probe=use_probe,
        probe_correction=ProbeCorrectionParams(kind=kind, check_s=check_s),
    )


@pytest.mark.parametrize(
    ("kind", "detail"),
    [
        ("online", "online map identified from 5 probe samples"),  # ticks 0, 10, 20, 30, 40
        ("none", "none correction: nothing to identify"),
    ],
)
def test_the_probe_check_event_comes_once_when_the_check_ends(kind, detail, rng):
    blocks = blocks_for(check_params(kind))
    assert blocks.checking
    # hand off the handle, someone pressing the probe tip
    pressing = lambda k: np.array([1.5, -1.0, 6.0]) * np.sin(np.pi * k / 50.0) ** 2  # noqa: E731
    events = []
    for k, reading in enumerate(session(200, rng, hand_from=10**9, contact_B=pressing)):
        cycle = control_cycle(blocks, reading, k * DT, DT)
        events += [(k, event) for event in cycle.events if event.name != "mode"]
        checking = k < 50  # check_s = 0.1 s of 2 ms cycles
        assert cycle.estimate["probe_check"][0] == float(checking)
        assert cycle.estimate["ready"][0] == float(not checking)
        # the robot holds still through the check, and the session goes on
        assert cycle.verdict.cause is None
        assert not cycle.status & Status.NOT_READY
        if checking:
            np.testing.assert_array_equal(cycle.verdict.twist_B, np.zeros(6))
    assert events == [(50, Event("probe check", detail, f"probe check done: {detail}"))]
    assert not blocks.checking


def test_no_probe_check_event_without_a_probe_in_the_policy(rng):
    blocks = blocks_for(check_params("online"), SessionPolicy(LimitParams()))
    assert not blocks.checking
    cycles = [
        control_cycle(blocks, reading, k * DT, DT)
        for k, reading in enumerate(session(100, rng, hand_from=10**9))
    ]
    assert [event for cycle in cycles for event in cycle.events if event.name != "mode"] == []
    # without a probe the check is not masked: an estimator that waits for one is not ready
    assert cycles[0].verdict.cause == "the controller stopped: estimator not ready (rebiasing)"


@pytest.mark.parametrize(("check_s", "use_probe"), [(0.0, True), (0.1, False)])
def test_no_probe_check_event_without_a_check(check_s, use_probe, rng):
    blocks = blocks_for(
        check_params("online", check_s, use_probe), SessionPolicy(LimitParams(), probe="FSE103")
    )
    assert not blocks.checking
    for k, reading in enumerate(session(100, rng, hand_from=10**9)):
        cycle = control_cycle(blocks, reading, k * DT, DT)
        assert [event for event in cycle.events if event.name != "mode"] == []
        assert cycle.verdict.cause is None


def test_probe_drift_is_announced_once_each_way(rng):
    # the probe sensor alone reads 5 N across the probe's axis for 0.8 s: the wrist disagrees
    across_P = R_SP_SEED.T @ np.array([5.0, 0.0, 0.0])
    blocks = blocks_for(check_params("none", check_s=0.0))
    readings = session(
        1500, rng, hand_from=10**9, probe_only_P=lambda k: across_P if k < 400 else np.zeros(3)
    )
    events = []
    for k, reading in enumerate(readings):
        cycle = control_cycle(blocks, reading, k * DT, DT)
        events += [
            (k, cycle.estimate["probe_mismatch"][0], e) for e in cycle.events if e.name != "mode"
        ]
    assert [e.name for _, _, e in events] == ["probe drift", "probe drift"]
    (k_on, mismatch_on, on), (k_off, mismatch_off, off) = events
    assert 0 < k_on < 400 < k_off
    assert mismatch_on > 2.0 > mismatch_off  # the threshold, crossed each way
    text = "the probe sensor disagrees with the wrist sensor by 2.0 N across the probe: recheck it"
    assert on == Event("probe drift", text, f"warning: {text}")
    text = "the two sensors agree again (2.0 N)"
    assert off == Event("probe drift", text, text)


def test_following_the_breath_is_announced_when_it_starts_and_stops(rng):
    # the probe pressed 6 N along its axis (tip at -z of the wrist sensor) from cycle 300 to 900,
    # no hand: the follow starts with the contact and stops after it; the stop is told a breath
    # (FOLLOW_GAP_S) after the start at the earliest
    def contact_B(k: int) -> np.ndarray:
        return 6.0 * (wrist_turn(k) @ np.array([0.0, 0.0, 1.0])) if 300 <= k < 900 else np.zeros(3)

    blocks = blocks_for(
        check_params("none", check_s=0.0),
        controller=ControllerParams(follow=FollowParams(enabled=True)),
    )
    events, flags = [], []
    gap = round(FOLLOW_GAP_S / DT)
    for k, reading in enumerate(session(400 + gap, rng, hand_from=10**9, contact_B=contact_B)):
        cycle = control_cycle(blocks, reading, k * DT, DT)
        events += [(k, e) for e in cycle.events if e.name != "mode"]
        flags.append(int(cycle.command["status"][0]) & int(Status.FOLLOWING))
    assert [e.name for _, e in events] == ["follow", "follow"]
    (k_on, on), (k_off, off) = events
    assert 300 < k_on < 350  # the probe's filter crossing the 3 N contact
    assert k_off == k_on + gap
    assert re.fullmatch(
        r"ROBOT FOLLOWS THE BREATH: following the breath along the probe about \d\.\d N",
        on.announcement,
    )
    assert off == Event(
        "follow", "no longer following the breath", "robot: no longer following the breath"
    )
    stopped = next(k for k in range(k_on, len(flags)) if not flags[k])
    assert 900 < stopped < 1000
    assert all(flags[k_on:stopped])
    assert not any(flags[:k_on])
    assert not any(flags[stopped:])
