"""The clinical metric set: effort, force stability, image stability, time and path of one task run.

A run of the clinical study (`hoh_cosim.study.clinical`) is one operator doing one task (`view`:
reach a view and hold it; `scan`: a line across the abdomen; `press`: press to a force), assisted by
the robot (a `plant`) or freehand (a `freehand` probe), on a phantom that may breathe. The metrics:

- effort, over the whole task (from the hand taking the probe, `start_s`, to the end):
  `hand_force_rms_N` the RMS magnitude of the hand's true force on the probe (operator.F_hand_B:
  on the robot what it pushes the handle with; freehand what holds, moves and presses the probe,
  weight included), `hand_force_peak_N` its largest magnitude, `hand_impulse_N_s` its integral;
- force stability: `contact_losses` times the tip left the phantom after the first touch;
  `contact_force_mean_N`, `contact_force_std_N` of the phantom's force along the pressing
  direction over the measurement window (below);
- image stability, over the measurement window: the tip's motion above `JITTER_HZ` (zero-phase
  Butterworth high-pass: tremor, oscillation, jerks; the slow task motion and breathing, under
  0.35 Hz, left out), expressed in the probe's own frame T at each instant (z_T the beam, x_T the
  array in the image plane, y_T out of it): `jitter_lateral_mm` (x_T), `jitter_axial_mm` (z_T),
  `jitter_elevation_mm` (y_T), RMS each, `jitter_image_mm` the RMS in the image plane (lateral and
  axial together), `jitter_rotation_deg` the RMS of the orientation's high-passed rotation vector
  (its norm);
- `task_time_s`: from `start_s` until the task's goal first held for `GOAL_HOLD_S`: `view` the
  tip within `VIEW_TOLERANCE_M` of the view across the pressing direction and the contact force
  within `FORCE_TOLERANCE` of the target; `press` the force within the tolerance; `scan` the
  tip `SCAN_COVERAGE` of the line along it. None (and a note) if never;
- `path_rms_error_m`: RMS distance between the tip and where the hand wants it (operator.p_ref_B),
  across the pressing direction, over the measurement window;
- recovery from the patient moving away (the clinical study's planted contact loss: a `breathing`
  component with `away_m` > 0, else None): `recovery_time_s` from the move's start (`away_s`) to
  the first time the contact force along the pressing direction is back at `RECOVERY_LEVEL` of
  its mean over the `RECOVERY_BEFORE_S` before the move, counted once the contact was lost or fell
  under `RECOVERY_LOST` of that mean (0 if it never did: the contact was kept; None and a note if
  it never came back), `recovery_peak_N` the largest such force from the move's start to the end;
- hold-on-release (`hoh_cosim.control.hold`), from the controller's recorded status (None without
  one): `hold_s` how long the robot held the contact (the HOLDING flag); `hold_contact_force_std_N`
  the std of the phantom's force along the pressing direction while it held with the hand off the
  handle (operator.F_hand_B zero), from `HOLD_SETTLE_S` after the hand let go: the force through
  the breaths with nobody holding the probe; `hold_contact_force_change_N` how far the hold moved
  that force from its value at the release (the issue's "at its value at release"): its mean over
  the same hands-off window less its mean over the `RELEASE_WINDOW_S` before the hand began to
  open (`operator.let_go_ramp_s` before it was off), the largest in size over the run's let-gos,
  signed (negative: the hold let the contact fall); `hold_contact_losses` the times the tip left the
  phantom while the robot held; `handbacks` the hand-backs (a touch of the handle: the
  HANDING_BACK flag), `handback_jump_m` the farthest the tip moved from where it was at a
  hand-back's start during its blend (the largest over the run's hand-backs): it holds the hand's
  own first motion and the breath's along the probe too, so it bounds the jump from above;
  `handback_unasked_m` the part the hand did not ask for: the farthest the tip's displacement
  across the pressing direction departed from the hand's reference's (operator.p_ref_B) during the
  blend.

The measurement window starts `CONTACT_SETTLE_S` after the first touch (for `view`, after the reach
is over, if later) and ends with the run. Every number comes from the recording and the scenario's
parameters; one the run cannot give is None with a note.
"""

from __future__ import annotations

import math

import numpy as np

from hoh_cosim.cosim.recording import Recording
from hoh_cosim.cosim.scenario import ComponentSpec, Scenario

__all__ = [
    "ARM_KINDS",
    "CLINICAL_METRICS",
    "CONTACT_SETTLE_S",
    "JITTER_HZ",
    "clinical_metrics",
    "measurement_window",
]

ARM_KINDS = ("plant", "freehand")
"""What holds the probe in a clinical run: the robot (UR5 plant) or the hand alone."""
JITTER_HZ = 2.0
"""[Hz] The jitter band starts here: above breathing (12-20 per minute, harmonics under 1 Hz) and
the tasks' motions (under 0.5 Hz), below physiological tremor (8-12 Hz)."""
CONTACT_SETTLE_S = 2.0
"""[s] After the first touch (or the reach) the hand's force loop settles; the window starts then."""
VIEW_TOLERANCE_M = 2e-3
FORCE_TOLERANCE = 0.10
SCAN_COVERAGE = 0.95
GOAL_HOLD_S = 0.5
HOLD_SETTLE_S = 1.0
"""[s] After the hand let go, the hold takes over the hand's share of the force (the opening hand
is a 0.1 s step of a few newtons); the force's std is measured from then."""
RELEASE_WINDOW_S = 0.5
"""[s] The contact force at the release is its mean over this long before the hand began to open:
the hand's press loop, not one instant of its tremor."""
RECOVERY_BEFORE_S = 2.0
"""[s] The contact force before the patient moved away is its mean over this long before the move."""
RECOVERY_LOST = 0.5
"""The contact counts as lost off the phantom or under this fraction of its force before the move."""
RECOVERY_LEVEL = 0.8
"""The contact is back once its force is at or above this fraction of its force before the move."""
RECOVERY_METRICS = ("recovery_time_s", "recovery_peak_N")
HOLD_METRICS = (
    "hold_s",
    "hold_contact_force_std_N",
    "hold_contact_force_change_N",
    "hold_contact_losses",
    "handbacks",
    "handback_jump_m",
    "handback_unasked_m",
)
CLINICAL_METRICS = (
    "hand_force_rms_N",
    "hand_force_peak_N",
    "hand_impulse_N_s",
    "contact_losses",
    "contact_force_mean_N",
    "contact_force_std_N",
    "jitter_lateral_mm",
    "jitter_axial_mm",
    "jitter_elevation_mm",
    "jitter_image_mm",
    "jitter_rotation_deg",
    "task_time_s",
    "path_rms_error_m",
    *RECOVERY_METRICS,
    *HOLD_METRICS,
)
"""Every metric of the set, in the order of the tables."""


def _signal(rec: Recording, spec: ComponentSpec, port: str) -> np.ndarray:
    return rec[f"{spec.name}.{port}"]


def _arm(scenario: Scenario) -> ComponentSpec:
    arm = scenario.component_of_kinds(ARM_KINDS)
    assert arm is not None, "the scenario loader checks that a plant or a freehand probe exists"
    return arm


def _first_held(t: np.ndarray, ok: np.ndarray, hold_s: float) -> float | None:
    """The first time from which `ok` stays true for `hold_s`."""
    if not ok.any():
        return None
    edges = np.diff(np.concatenate([[0], ok.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    for a, b in zip(starts, ends, strict=True):
        if t[b - 1] - t[a] >= hold_s - 1e-9:
            return float(t[a])
    return None


def measurement_window(scenario: Scenario, rec: Recording) -> tuple[np.ndarray, float | None]:
    """(rows of the measurement window, time of the first touch or None)."""
    op = scenario.component_of_kind("operator")
    arm = _arm(scenario)
    assert op is not None, "the scenario loader checks that an operator exists"
    p = op.params
    t = rec.time
    touching = (_signal(rec, arm, "penetration")[:, 0] > 0.0) & (t >= p.start_s)
    if not touching.any():
        return np.zeros(len(t), dtype=bool), None
    first = float(t[np.argmax(touching)])
    begin = first
    if p.task == "view":
        begin = max(begin, p.start_s + p.reach_s)
    return t >= begin + CONTACT_SETTLE_S, first


def _rotvecs(R: np.ndarray) -> np.ndarray:
    """Rotation vectors of the (n, 3, 3) rotations R (angles well below π)."""
    vee = 0.5 * np.stack(
        [R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1
    )
    s = np.linalg.norm(vee, axis=1)
    c = 0.5 * (np.trace(R, axis1=1, axis2=2) - 1.0)
    angle = np.arctan2(s, c)
    scale = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 1.0)
    return vee * scale[:, None]


def jitter(t: np.ndarray, p_BT: np.ndarray, R_BT: np.ndarray, dt: float) -> dict[str, float | None]:
    """The jitter metrics (module docstring) of tip positions (n, 3) and orientations (n, 9)."""
    from hoh_cosim.cosim.metrics import high_passed

    names = (
        "jitter_lateral_mm",
        "jitter_axial_mm",
        "jitter_elevation_mm",
        "jitter_image_mm",
        "jitter_rotation_deg",
    )
    # sosfiltfilt needs a few times its padding: under 2 s the band's edge is not resolved
    if len(t) < 2 or t[-1] - t[0] < 2.0:
        return dict.fromkeys(names)
    R = R_BT.reshape(-1, 3, 3)
    hp = high_passed(p_BT, JITTER_HZ, dt)
    # into T at each instant: e_T = R_BTᵀ e_B
    e_T = np.einsum("nji,nj->ni", R, hp)
    rms = np.sqrt(np.mean(e_T**2, axis=0))
    relative = np.einsum("ji,njk->nik", R[0], R)  # R(0)ᵀ R(t)
    rot = high_passed(_rotvecs(relative), JITTER_HZ, dt)
    return {
        names[0]: 1e3 * float(rms[0]),
        names[1]: 1e3 * float(rms[2]),
        names[2]: 1e3 * float(rms[1]),
        names[3]: 1e3 * float(math.hypot(rms[0], rms[2])),
        names[4]: math.degrees(float(np.sqrt(np.mean(np.sum(rot**2, axis=1))))),
    }


def _task_time(scenario: Scenario, rec: Recording, pressing: np.ndarray) -> float | None:
    op = scenario.component_of_kind("operator")
    assert op is not None
    p = op.params
    arm = _arm(scenario)
    t = rec.time
    after = t >= p.start_s
    tip = _signal(rec, arm, "p_BT_B")
    d = p.press_direction_B
    in_force = np.abs(pressing - p.target_force_N) <= FORCE_TOLERANCE * p.target_force_N
    if p.task == "press":
        ok = in_force
    elif p.task == "view":
        origin = tip[np.argmax(after)]
        goal = origin + p.length_m * p.direction_B
        error = tip - goal
        across = error - np.outer(error @ d, d)
        ok = in_force & (np.linalg.norm(across, axis=1) <= VIEW_TOLERANCE_M)
    elif p.task == "scan":
        origin = tip[np.argmax(after)]
        ok = (tip - origin) @ p.direction_B >= SCAN_COVERAGE * p.length_m
    else:
        return None
    when = _first_held(t, ok & after, GOAL_HOLD_S)
    return None if when is None else when - p.start_s


def clinical_metrics(scenario: Scenario, rec: Recording) -> tuple[dict[str, object], list[str]]:
    """The metrics of the module docstring, and notes on what could not be measured."""
    op = scenario.component_of_kind("operator")
    assert op is not None, "the scenario loader checks that an operator exists"
    arm = _arm(scenario)
    p = op.params
    t = rec.time
    dt = scenario.dt_s
    m: dict[str, object] = dict.fromkeys(CLINICAL_METRICS)
    notes: list[str] = []

    task = t >= p.start_s
    hand = np.linalg.norm(_signal(rec, op, "F_hand_B")[task], axis=1)
    if len(hand) > 1:
        m["hand_force_rms_N"] = float(np.sqrt(np.mean(hand**2)))
        m["hand_force_peak_N"] = float(np.max(hand))
        m["hand_impulse_N_s"] = float(np.sum(0.5 * (hand[1:] + hand[:-1])) * dt)
    else:
        notes.append("clinical: the run ends before the task starts: no effort metrics")

    pressing = -_signal(rec, arm, "F_contact_B") @ p.press_direction_B
    window, first = measurement_window(scenario, rec)
    depth = _signal(rec, arm, "penetration")[:, 0]
    if first is None:
        notes.append("clinical: the probe never touched the phantom")
        m["contact_losses"] = 0
    else:
        touching = depth[t >= first] > 0.0
        m["contact_losses"] = int(np.count_nonzero(touching[:-1] & ~touching[1:]))
    if window.sum() > 1:
        m["contact_force_mean_N"] = float(np.mean(pressing[window]))
        m["contact_force_std_N"] = float(np.std(pressing[window]))
        m.update(
            jitter(
                t[window],
                _signal(rec, arm, "p_BT_B")[window],
                _signal(rec, arm, "R_BT")[window],
                dt,
            )
        )
        if m["jitter_image_mm"] is None:
            notes.append("clinical: the measurement window is under 2 s: no jitter metrics")
        error = (_signal(rec, arm, "p_BT_B") - _signal(rec, op, "p_ref_B"))[window]
        d = p.press_direction_B
        across = error - np.outer(error @ d, d)
        m["path_rms_error_m"] = float(np.sqrt(np.mean(np.sum(across**2, axis=1))))
    elif first is not None:
        notes.append(
            f"clinical: the run ends less than {CONTACT_SETTLE_S:g} s after the first touch or "
            "the reach: no window for the stability metrics"
        )
    recovery, recovery_notes = _recovery_metrics(scenario, rec, pressing, depth)
    m.update(recovery)
    notes.extend(recovery_notes)
    m.update(_hold_metrics(scenario, rec, pressing, depth))
    m["task_time_s"] = _task_time(scenario, rec, pressing)
    if m["task_time_s"] is None and p.task in ("view", "press", "scan"):
        notes.append(f"clinical: the {p.task} task's goal was never reached and held")
    return m, notes


def _recovery_metrics(
    scenario: Scenario, rec: Recording, pressing: np.ndarray, depth: np.ndarray
) -> tuple[dict[str, object], list[str]]:
    """The recovery metrics (module docstring), and notes on what could not be measured."""
    m: dict[str, object] = dict.fromkeys(RECOVERY_METRICS)
    breathing = scenario.component_of_kind("breathing")
    if breathing is None or breathing.params.away_m <= 0.0:
        return m, []
    t = rec.time
    away_s = breathing.params.away_s
    after = t >= away_s
    if not after.any():
        return m, ["clinical: the run ends before the patient moves away: no recovery metrics"]
    m["recovery_peak_N"] = float(np.max(pressing[after]))
    before = (t >= away_s - RECOVERY_BEFORE_S) & (t < away_s)
    level = float(np.mean(pressing[before])) if before.any() else 0.0
    if level <= 0.0:
        return m, ["clinical: no contact force before the patient moved away: no recovery time"]
    lost = after & ((depth <= 0.0) | (pressing < RECOVERY_LOST * level))
    if not lost.any():
        m["recovery_time_s"] = 0.0
        return m, []
    back = (pressing >= RECOVERY_LEVEL * level) & (np.arange(len(t)) > np.argmax(lost))
    if not back.any():
        return m, [
            f"clinical: the contact never came back to {RECOVERY_LEVEL:.0%} of its force before "
            "the patient moved away by the end of the run"
        ]
    m["recovery_time_s"] = float(t[np.argmax(back)] - away_s)
    return m, []


def _runs(flag: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index pairs of the runs of True in `flag`."""
    edges = np.diff(np.concatenate([[0], flag.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def _hold_metrics(
    scenario: Scenario, rec: Recording, pressing: np.ndarray, depth: np.ndarray
) -> dict[str, object]:
    """The hold-on-release metrics (module docstring)."""
    from hoh_cosim.control.supervisor import Status

    m: dict[str, object] = dict.fromkeys(HOLD_METRICS)
    controller = scenario.component_of_kind("controller")
    op = scenario.component_of_kind("operator")
    if controller is None or op is None or f"{controller.name}.status" not in rec:
        return m
    t = rec.time
    status = rec[f"{controller.name}.status"][:, 0].astype(np.int64)
    holding = (status & int(Status.HOLDING)) != 0
    back = (status & int(Status.HANDING_BACK)) != 0
    dt = scenario.dt_s
    m["hold_s"] = float(np.count_nonzero(holding) * dt)
    touching = depth > 0.0
    m["hold_contact_losses"] = int(np.count_nonzero(holding[1:] & touching[:-1] & ~touching[1:]))
    # the hand off the handle, HOLD_SETTLE_S after it let go
    off = np.linalg.norm(_signal(rec, op, "F_hand_B"), axis=1) == 0.0
    off &= t >= op.params.start_s
    let_gos = _runs(off)
    settled = np.zeros(len(t), dtype=bool)
    for a, b in let_gos:
        settled[a:b] = t[a:b] >= t[a] + HOLD_SETTLE_S
    window = holding & settled
    if np.count_nonzero(window) > 1:
        m["hold_contact_force_std_N"] = float(np.std(pressing[window]))
    changes = []
    for a, b in let_gos:
        held = window[a:b]
        opened = t[a] - op.params.let_go_ramp_s  # the hand began to open
        before = (t >= opened - RELEASE_WINDOW_S) & (t < opened)
        if np.count_nonzero(held) > 1 and np.count_nonzero(before) > 1:
            changes.append(float(np.mean(pressing[a:b][held]) - np.mean(pressing[before])))
    if changes:
        m["hold_contact_force_change_N"] = max(changes, key=abs)
    episodes = _runs(back)
    m["handbacks"] = len(episodes)
    if episodes:
        tip = rec[f"{_arm(scenario).name}.p_BT_B"]
        ref = _signal(rec, op, "p_ref_B")
        d = op.params.press_direction_B
        m["handback_jump_m"] = max(
            float(np.max(np.linalg.norm(tip[a:b] - tip[a], axis=1))) for a, b in episodes
        )
        unasked = 0.0
        for a, b in episodes:
            e = (tip[a:b] - tip[a]) - (ref[a:b] - ref[a])
            across = e - np.outer(e @ d, d)
            unasked = max(unasked, float(np.max(np.linalg.norm(across, axis=1))))
        m["handback_unasked_m"] = unasked
    return m
