"""What a run measured: the metric set a scenario names, computed from its recording.

Each set answers the question of one of the seed's experiments (seed 000, section 4), with the names
`summary.json` uses. Every metric is computed from the recorded signals and the scenario's own
parameters (the truth the simulation knows); none is a constant. A metric that the run cannot give
(too short, no contact ever made) is None with a note saying why, never a made-up number.

- circles (Fig. 20, 21), while the operator draws (from the end of the speed ramp):
  `path_rms_error_m` RMS distance of the tip from where the hand wants it; `hand_force_rms_N` RMS
  magnitude of the true hand force; `filter_lag_ms` how far the filtered hand force trails the raw,
  aligned measurement at the circle's frequency (the seed's "lag added by the filter", ~10 ms);
  `estimate_rms_error_N` RMS magnitude of filtered estimate minus true hand force;
  `velocity_hf_rms_m_s` RMS of the tip's velocity above 4x the circle frequency (zero-phase
  high-pass): the jitter and the oscillation a loop near its stability limit adds, and
  `velocity_hf_late_rms_m_s` the same over the last whole circle only: whether an oscillation is
  sustained to the end or was stopped (by the variable law's oscillation watch). Also
  `estimate_lag_ms`: the filtered estimate behind the true force (sensor latency, packets, filter).
  A negative lag is a lead: the constant-acceleration filter extrapolates between packets, and the
  held raw reading is itself half a packet period late on average.
- static_noise (Fig. 18, 19), once the estimator is ready: `noise_max_abs_raw_N` and
  `noise_max_abs_filtered_N` max |hand force estimate - true hand force| per base axis x, y, z, raw
  (aligned, compensated, held packets) and filtered; `noise_attenuation` their ratio;
  `rest_motion_m` how far the untouched tip moved in that window (noise that got past the deadband).
- gravity_calibration (Fig. 16, 17): every FT-150 packet delivered while the robot holds a pose is
  averaged; the 10-parameter identification of eq. 4-8 runs on the averages (as `hoh-cosim
  identify-gravity` would on the `poses.csv` written beside). `mass_kg`, `com_m` (x, y, z in S),
  `mass_error_pct` (signed, against the simulated tool), `com_error_mm` (distance), and the force
  residuals' RMS per sensor axis before (bias removed) and after (weight model removed too):
  `residual_rms_before_N`, `residual_rms_after_N`; the torque ones with `_Nm`.
- contact_scan (3.F.2, 3.F.3), from the first touch: `contact_losses` times the tip left the
  phantom, `contact_force_mean_N` and `contact_force_std_N` of the force the phantom pushes back with
  along the pressing direction (from 2 s after the first touch), `max_bounce_m` the highest the tip
  rose above the surface after it, `orientation_drift_deg` the largest angle the probe turned from
  its orientation at the first touch (when `plant.R_BT` is recorded).
- release (5.C): `release_drift_m` how far the tip moved after the hand let go (to the end of the
  run), `release_settle_s` how long until its speed stayed under 1 mm/s.
- teleecho (seed 001, 6.2), the probe pressing and sliding on the phantom, for the Panda under
  Cartesian impedance or the UR5 under position-based impedance: over the slide (from its start to
  the end) `y_tracking_rms_m` RMS of the tip's distance from the reference along the slide's axis,
  `contact_force_mean_N` and `contact_force_std_N` of the phantom's force along the surface normal;
  from the start of the run, `orientation_error_max_rad` the largest angle between the tip's
  orientation and its start orientation (the reference); from the first touch, `contact_losses`.
- probe_data (seed 000, 3.B.2, 4.A, Fig. 6 and 14): forces pushed on the probe tip with the hand off
  the handle during the estimator's probe check, one sample per probe packet: the rebiased reading m
  and the compensated wrist force (the reference), both in the probe sensor's frame P.
  `probe_samples`; per axis of P the correlation coefficient and the RMS error against the reference
  of the raw reading (`probe_raw_correlation`, `probe_raw_rms_N`) and of the estimator's correction
  (`probe_corrected_correlation`, `probe_corrected_rms_N`; for the online map its prediction before it
  learns from the sample), and `probe_corrected_rms_late_N` over the second half of the samples.
- clinical (the clinical study, freehand or assisted, breathing or not): effort, force stability,
  image stability, task time and path error of one task (`hoh_cosim.cosim.clinical` defines them).
- with a controller: `controller_flags`, what its limits did once the estimator was ready ("ok" if
  nothing), and `controller_stop_s`, how long it commanded a stop then.
- every run: `realtime_factor` (simulated / wall-clock seconds) and `wall_s`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hoh_cosim.control.gravity import identify_gravity
from hoh_cosim.control.supervisor import STOP_FLAGS, Status
from hoh_cosim.cosim.metrics import high_passed, sinusoid_phase
from hoh_cosim.cosim.recording import Recording
from hoh_cosim.cosim.scenario import (
    TELEECHO_ARMS,
    TELEECHO_CONTROLLERS,
    ComponentSpec,
    Scenario,
)
from hoh_cosim.errors import IdentificationError

__all__ = ["SETTLE_SPEED_M_S", "Report", "compute_report", "lag_in_window"]

SETTLE_SPEED_M_S = 1e-3
"""[m/s] Below this the tip counts as standing still after a release."""
CONTACT_SETTLE_S = 2.0
"""[s] After the first touch the operator's force loop settles; the force statistics start then."""


@dataclass
class Report:
    """Metrics (flat, JSON-ready), notes on anything that could not be measured, extra files."""

    metrics: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)  # file name -> text
    data: dict[str, Any] = field(default_factory=dict)  # intermediate results, for the plots


def _rms_norm(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(x * x, axis=1))))


def _component(scenario: Scenario, kind: str) -> ComponentSpec:
    spec = scenario.component_of_kind(kind)
    assert spec is not None, f"the scenario loader checks that a {kind} is present"
    return spec


def _signal(rec: Recording, spec: ComponentSpec, port: str) -> np.ndarray:
    return rec[f"{spec.name}.{port}"]


def lag_in_window(
    t: np.ndarray, reference: np.ndarray, signal: np.ndarray, frequency_hz: float
) -> float:
    """Lag [s] of `signal` behind `reference` (both (n, k)) at `frequency_hz`: the phase lag of
    each column's sinusoid fit, weighted by the reference's amplitude in that column."""
    lags, weights = [], []
    for j in range(reference.shape[1]):
        a_ref, phi_ref = sinusoid_phase(t, reference[:, j], frequency_hz)
        _, phi_sig = sinusoid_phase(t, signal[:, j], frequency_hz)
        dphi = (phi_ref - phi_sig + math.pi) % (2.0 * math.pi) - math.pi
        lags.append(dphi / (2.0 * math.pi * frequency_hz))
        weights.append(a_ref)
    return float(np.average(lags, weights=weights)) if sum(weights) > 0 else math.nan


HF_FACTOR = 4.0
"""The jitter band of a circle run starts at this many times the circle's frequency."""


def _circles(scenario: Scenario, rec: Recording, report: Report) -> None:
    op, plant, est = (_component(scenario, k) for k in ("operator", "plant", "estimator"))
    p = op.params
    start = p.start_s + p.ramp_s
    frequency = 1.0 / p.period_s
    periods = math.floor((rec.time[-1] - start) / p.period_s + 1e-9)
    m = report.metrics
    if periods < 1:
        report.notes.append(
            f"circles: the run ends {rec.time[-1]:g} s, before one whole circle after the speed "
            f"ramp ({start:g} + {p.period_s:g} s): no circle metrics"
        )
        m.update(
            dict.fromkeys(
                (
                    "path_rms_error_m",
                    "hand_force_rms_N",
                    "filter_lag_ms",
                    "estimate_lag_ms",
                    "estimate_rms_error_N",
                    "velocity_hf_rms_m_s",
                    "velocity_hf_late_rms_m_s",
                )
            )
        )
        return
    window = (rec.time >= start) & (rec.time <= start + periods * p.period_s + 1e-9)
    t = rec.time[window]
    hand = _signal(rec, op, "F_hand_B")[window]
    estimate = _signal(rec, est, "F_hand_B")[window]
    raw = _signal(rec, est, "F_hand_meas_B")[window]
    axes = [i for i in range(3) if np.ptp(_signal(rec, op, "p_ref_B")[window, i]) > 0.0]
    m["path_rms_error_m"] = _rms_norm(
        _signal(rec, plant, "p_BT_B")[window] - _signal(rec, op, "p_ref_B")[window]
    )
    m["hand_force_rms_N"] = _rms_norm(hand)
    m["filter_lag_ms"] = 1e3 * lag_in_window(t, raw[:, axes], estimate[:, axes], frequency)
    m["estimate_lag_ms"] = 1e3 * lag_in_window(t, hand[:, axes], estimate[:, axes], frequency)
    m["estimate_rms_error_N"] = _rms_norm(estimate - hand)
    hf = high_passed(
        _signal(rec, plant, "twist_B")[window, :3], HF_FACTOR * frequency, scenario.dt_s
    )
    m["velocity_hf_rms_m_s"] = _rms_norm(hf)
    m["velocity_hf_late_rms_m_s"] = _rms_norm(hf[t >= t[-1] - p.period_s])


def _ready_window(rec: Recording, est: ComponentSpec, report: Report, what: str) -> np.ndarray:
    ready = _signal(rec, est, "ready")[:, 0] > 0.5
    if not ready.any():
        report.notes.append(f"{what}: the estimator never became ready (still rebiasing)")
        return ready
    first = rec.time[np.argmax(ready)]
    return ready & (rec.time >= first + 1.0)  # past the filters' start-up transient


def _static_noise(scenario: Scenario, rec: Recording, report: Report) -> None:
    est = _component(scenario, "estimator")
    op = scenario.component_of_kind("operator")
    window = _ready_window(rec, est, report, "static_noise")
    m = report.metrics
    names = (
        "noise_max_abs_raw_N",
        "noise_max_abs_filtered_N",
        "noise_attenuation",
        "rest_motion_m",
    )
    if window.sum() < 2:
        report.notes.append("static_noise: less than a second after the rebias: no noise metrics")
        m.update(dict.fromkeys(names))
        return
    truth = _signal(rec, op, "F_hand_B")[window] if op is not None else 0.0
    raw = np.max(np.abs(_signal(rec, est, "F_hand_meas_B")[window] - truth), axis=0)
    filtered = np.max(np.abs(_signal(rec, est, "F_hand_B")[window] - truth), axis=0)
    m[names[0]] = raw.tolist()
    m[names[1]] = filtered.tolist()
    with np.errstate(divide="ignore", invalid="ignore"):
        m[names[2]] = [float(x) if math.isfinite(x) else None for x in raw / filtered]
    plant = scenario.component_of_kind("plant")
    if plant is None:
        m[names[3]] = None
    else:
        tip = _signal(rec, plant, "p_BT_B")[window]
        m[names[3]] = float(np.max(np.linalg.norm(tip - tip[0], axis=1)))


def pose_averages(
    rec: Recording, sequencer: ComponentSpec, plant: ComponentSpec, ft: ComponentSpec
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R_BS (n, 3, 3), mean raw wrench (n, 6), packets averaged (n,)) for every pose held."""
    holding = _signal(rec, sequencer, "holding")[:, 0] > 0.5
    pose = np.rint(_signal(rec, sequencer, "pose_index")[:, 0]).astype(int)
    counter = _signal(rec, ft, "counter")[:, 0]
    fresh = np.zeros_like(holding)
    fresh[1:] = counter[1:] > counter[:-1]
    wrench = _signal(rec, ft, "wrench_S")
    R = _signal(rec, plant, "R_BS")
    Rs, means, counts = [], [], []
    for j in np.unique(pose[holding]):
        rows = holding & (pose == j)
        packets = rows & fresh
        if not packets.any():
            continue
        held = np.flatnonzero(rows)
        Rs.append(R[held[len(held) // 2]].reshape(3, 3))
        means.append(wrench[packets].mean(axis=0))
        counts.append(int(packets.sum()))
    return np.array(Rs).reshape(-1, 3, 3), np.array(means).reshape(-1, 6), np.array(counts)


def _gravity_calibration(scenario: Scenario, rec: Recording, report: Report) -> None:
    from hoh_cosim.calibration import calibration_to_dict, poses_csv_text

    seq, plant, ft = (_component(scenario, k) for k in ("sequencer", "plant", "ft150"))
    R_BS, wrench, counts = pose_averages(rec, seq, plant, ft)
    m = report.metrics
    names = (
        "mass_kg",
        "com_m",
        "mass_error_pct",
        "com_error_mm",
        "residual_rms_before_N",
        "residual_rms_after_N",
        "residual_rms_before_Nm",
        "residual_rms_after_Nm",
    )
    m["poses"] = len(counts)
    m["packets_per_pose_min"] = int(counts.min()) if len(counts) else 0
    if len(counts):
        report.files["poses.csv"] = poses_csv_text(R_BS, wrench)
    try:
        cal = identify_gravity(R_BS, wrench, plant.params.g_B)
    except IdentificationError as exc:
        report.notes.append(f"gravity_calibration: {len(counts)} poses held: {exc}")
        m.update(dict.fromkeys(names))
        return

    report.files["calibration.json"] = json.dumps(calibration_to_dict(cal), indent=2) + "\n"
    report.data["calibration"] = cal
    report.data["poses"] = (R_BS, wrench)
    tool = plant.params.tool
    m["mass_kg"] = cal.mass_kg
    m["com_m"] = cal.com_m.tolist()
    m["mass_error_pct"] = 100.0 * (cal.mass_kg - tool.mass_kg) / tool.mass_kg
    m["com_error_mm"] = 1e3 * float(np.linalg.norm(cal.com_m - tool.p_SC_S))
    m["residual_rms_before_N"] = cal.residual_rms_before[:3].tolist()
    m["residual_rms_after_N"] = cal.residual_rms_after[:3].tolist()
    m["residual_rms_before_Nm"] = cal.residual_rms_before[3:].tolist()
    m["residual_rms_after_Nm"] = cal.residual_rms_after[3:].tolist()


def _contact_scan(scenario: Scenario, rec: Recording, report: Report) -> None:
    op, plant = (_component(scenario, k) for k in ("operator", "plant"))
    depth = _signal(rec, plant, "penetration")[:, 0]
    touching = depth > 0.0
    m = report.metrics
    names = (
        "contact_losses",
        "contact_force_mean_N",
        "contact_force_std_N",
        "max_bounce_m",
        "orientation_drift_deg",
    )
    if not touching.any():
        report.notes.append("contact_scan: the probe never touched the phantom")
        m.update(dict.fromkeys(names))
        m["contact_losses"] = 0
        return
    first = int(np.argmax(touching))
    after = touching[first:]
    m["contact_losses"] = int(np.count_nonzero(after[:-1] & ~after[1:]))
    pressing = -_signal(rec, plant, "F_contact_B") @ op.params.press_direction_B
    settled = rec.time >= rec.time[first] + CONTACT_SETTLE_S
    if settled.any():
        m["contact_force_mean_N"] = float(np.mean(pressing[settled]))
        m["contact_force_std_N"] = float(np.std(pressing[settled]))
    else:
        report.notes.append(
            f"contact_scan: the run ends less than {CONTACT_SETTLE_S:g} s after the first touch: "
            "no contact force statistics"
        )
        m["contact_force_mean_N"] = m["contact_force_std_N"] = None
    m["max_bounce_m"] = float(max(0.0, -np.min(depth[first:])))
    m["orientation_drift_deg"] = None
    if f"{plant.name}.R_BT" in rec:
        R = _signal(rec, plant, "R_BT")[first:].reshape(-1, 3, 3)
        # the angle of R(t₀)ᵀ R(t): cos θ = (tr - 1) / 2
        trace = np.einsum("ji,nji->n", R[0], R)
        angle = np.arccos(np.clip(0.5 * (trace - 1.0), -1.0, 1.0))
        m["orientation_drift_deg"] = math.degrees(float(np.max(angle)))
    else:
        report.notes.append("contact_scan: plant.R_BT not recorded: no orientation drift")


@dataclass(frozen=True)
class ProbeSamples:
    """One row per probe packet the estimator took during its probe check (all in P)."""

    t: np.ndarray  # (n,) [s]
    m: np.ndarray  # (n, 3) rebiased reading [N]
    corrected: np.ndarray  # (n, 3) the estimator's correction of it [N]
    reference: np.ndarray  # (n, 3) the compensated wrist force [N]


def probe_samples(scenario: Scenario, rec: Recording) -> ProbeSamples:
    """The probe check's samples: the rows where the probe sensor's counter moved while the
    estimator was checking (it steps after the sensor, every tick: it sees the packet that row)."""
    est, probe, plant = (_component(scenario, k) for k in ("estimator", "fse103", "plant"))
    counter = _signal(rec, probe, "counter")[:, 0]
    new = np.zeros(len(counter), dtype=bool)
    new[1:] = np.diff(counter) > 0
    rows = np.flatnonzero(new & (_signal(rec, est, "probe_check")[:, 0] > 0.5))
    R_BS = _signal(rec, plant, "R_BS")[rows].reshape(-1, 3, 3)
    F_B = _signal(rec, est, "F_hand_meas_B")[rows]
    # F_P = R_SPᵀ R_BSᵀ F_B, row by row
    F_S = np.einsum("nji,nj->ni", R_BS, F_B)
    reference = F_S @ est.params.R_SP
    return ProbeSamples(
        rec.time[rows],
        _signal(rec, est, "F_probe_meas_P")[rows],
        _signal(rec, est, "F_probe_corr_P")[rows],
        reference,
    )


def axis_correlation(x: np.ndarray, y: np.ndarray) -> list[float | None]:
    """Pearson's r per column of two (n, k) arrays; None for a column that does not vary."""
    out: list[float | None] = []
    for j in range(x.shape[1]):
        a, b = x[:, j] - x[:, j].mean(), y[:, j] - y[:, j].mean()
        den = math.sqrt(float(a @ a) * float(b @ b))
        out.append(float(a @ b) / den if den > 0.0 else None)
    return out


def axis_rms(error: np.ndarray) -> list[float]:
    return np.sqrt(np.mean(error**2, axis=0)).tolist()


def _probe_data(scenario: Scenario, rec: Recording, report: Report) -> None:
    est = _component(scenario, "estimator")
    m = report.metrics
    names = (
        "probe_raw_correlation",
        "probe_raw_rms_N",
        "probe_corrected_correlation",
        "probe_corrected_rms_N",
        "probe_corrected_rms_late_N",
    )
    if est.every != 1:
        report.notes.append(
            f"probe_data: the estimator steps every {est.every} ticks: the packets cannot be matched"
        )
        m["probe_samples"] = 0
        m.update(dict.fromkeys(names))
        return
    s = probe_samples(scenario, rec)
    report.data["probe_samples"] = s
    m["probe_samples"] = len(s.t)
    if len(s.t) < 4:
        report.notes.append("probe_data: fewer than 4 probe packets during the probe check")
        m.update(dict.fromkeys(names))
        return
    m["probe_raw_correlation"] = axis_correlation(s.m, s.reference)
    m["probe_raw_rms_N"] = axis_rms(s.m - s.reference)
    m["probe_corrected_correlation"] = axis_correlation(s.corrected, s.reference)
    m["probe_corrected_rms_N"] = axis_rms(s.corrected - s.reference)
    half = len(s.t) // 2
    m["probe_corrected_rms_late_N"] = axis_rms(s.corrected[half:] - s.reference[half:])


def _release(scenario: Scenario, rec: Recording, report: Report) -> None:
    op, plant = (_component(scenario, k) for k in ("operator", "plant"))
    on = _signal(rec, op, "hand_on")[:, 0] > 0.5
    falls = np.flatnonzero(on[:-1] & ~on[1:])
    m = report.metrics
    if len(falls) == 0:
        report.notes.append("release: the hand never let go of the handle")
        m["release_drift_m"] = m["release_settle_s"] = None
        return
    k = int(falls[-1]) + 1  # the first row with the hand off
    p = _signal(rec, plant, "p_BT_B")
    m["release_drift_m"] = float(np.linalg.norm(p[-1] - p[k]))
    speed = np.linalg.norm(_signal(rec, plant, "twist_B")[k:, :3], axis=1)
    moving = np.flatnonzero(speed >= SETTLE_SPEED_M_S)
    if len(moving) == 0:
        m["release_settle_s"] = 0.0
    elif moving[-1] == len(speed) - 1:
        report.notes.append(
            f"release: the tip still moves at {1e3 * speed[-1]:.3g} mm/s when the run ends: "
            "no settling time"
        )
        m["release_settle_s"] = None
    else:
        m["release_settle_s"] = float(rec.time[k + moving[-1] + 1] - rec.time[k])


def _teleecho_parts(scenario: Scenario) -> tuple[ComponentSpec, ComponentSpec]:
    plant = scenario.component_of_kinds(TELEECHO_ARMS)
    ctl = scenario.component_of_kinds(TELEECHO_CONTROLLERS)
    assert plant is not None, "the scenario loader checks that a plant exists"
    assert ctl is not None, "the scenario loader checks that a controller exists"
    return plant, ctl


def _teleecho(scenario: Scenario, rec: Recording, report: Report) -> None:
    plant, ctl = _teleecho_parts(scenario)
    task = ctl.params.task
    m = report.metrics
    p = _signal(rec, plant, "p_BT_B")
    R = _signal(rec, plant, "R_BT").reshape(-1, 3, 3)
    relative = np.einsum("ji,njk->nik", R[0], R)  # R_0ᵀ R(t)
    cos = np.clip((np.trace(relative, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    m["orientation_error_max_rad"] = float(np.max(np.arccos(cos)))
    depth = _signal(rec, plant, "penetration")[:, 0]
    touching = depth > 0.0
    if touching.any():
        after = touching[int(np.argmax(touching)) :]
        m["contact_losses"] = int(np.count_nonzero(after[:-1] & ~after[1:]))
    else:
        report.notes.append("teleecho: the probe never touched the phantom")
        m["contact_losses"] = 0
    # the reference at each row's time, from the task and the start, as the controller has it
    sliding = rec.time >= task.slide_start_s
    if not sliding.any():
        report.notes.append("teleecho: the run ends before the slide starts")
        m["y_tracking_rms_m"] = m["contact_force_mean_N"] = m["contact_force_std_N"] = None
        return
    ref = np.array([task.reference(float(t), p[0])[0] for t in rec.time[sliding]])
    along = (p[sliding] - ref) @ task.axis_B
    m["y_tracking_rms_m"] = float(np.sqrt(np.mean(along**2)))
    normal = _signal(rec, plant, "F_contact_B")[sliding] @ plant.params.phantom.plane_normal_B
    m["contact_force_mean_N"] = float(np.mean(normal))
    m["contact_force_std_N"] = float(np.std(normal))


def _controller_status(scenario: Scenario, rec: Recording, report: Report) -> None:
    """Which safety flags the controller raised once the estimator was ready: a person reading the
    metrics should know when a run's motion was clamped or stopped."""
    ctl = scenario.component_of_kind("controller")
    est = scenario.component_of_kind("estimator")
    if ctl is None:
        return
    # a tick without values (libcosim shows none before its first step) raises no flag
    status = np.rint(np.nan_to_num(_signal(rec, ctl, "status")[:, 0])).astype(int)
    if est is not None:
        ready = _signal(rec, est, "ready")[:, 0] > 0.5
        # the controller sees `ready` at its next cycle: skip that first cycle's "not ready"
        lag = ctl.every + 1
        ready[lag:] &= ready[:-lag]
        ready[:lag] = False
        status = status[ready]
    seen = Status(int(np.bitwise_or.reduce(status))) if status.size else Status(0)
    report.metrics["controller_flags"] = seen.describe()
    report.metrics["controller_stop_s"] = float(
        np.count_nonzero(status & int(STOP_FLAGS)) * (rec.time[1] - rec.time[0])
    )


def _clinical(scenario: Scenario, rec: Recording, report: Report) -> None:
    """The clinical study's set (`hoh_cosim.cosim.clinical`)."""
    from hoh_cosim.cosim.clinical import clinical_metrics

    metrics, notes = clinical_metrics(scenario, rec)
    report.metrics.update(metrics)
    report.notes.extend(notes)


def _no_metrics(scenario: Scenario, rec: Recording, report: Report) -> None:
    """The 'none' set: only what every run reports."""


# One entry per metric set of `METRIC_SETS` (scenario.py), which a unit test checks.
_SETS: dict[str, Callable[[Scenario, Recording, Report], None]] = {
    "none": _no_metrics,
    "circles": _circles,
    "static_noise": _static_noise,
    "gravity_calibration": _gravity_calibration,
    "contact_scan": _contact_scan,
    "release": _release,
    "teleecho": _teleecho,
    "probe_data": _probe_data,
    "clinical": _clinical,
}


def compute_report(scenario: Scenario, rec: Recording) -> Report:
    """The scenario's metric set, the controller's flags, and the run's speed."""
    report = Report()
    _SETS[scenario.metrics](scenario, rec, report)
    _controller_status(scenario, rec, report)
    report.metrics["wall_s"] = rec.wall_s
    report.metrics["realtime_factor"] = scenario.duration_s / rec.wall_s if rec.wall_s > 0 else None
    return report
