"""Every metric a run can write into `summary.json`: its unit and its definition, in one table.

The metric sets are computed in `hoh_cosim.cosim.report` (the seed's experiments) and
`hoh_cosim.cosim.clinical` (the clinical study), whose docstrings give the details; this table is
what the documentation's metric reference is generated from. The scenario tests check that every
metric a run writes is here, so the reference cannot fall behind the code.

A list-valued metric holds one value per axis (x, y, z of the frame its definition names).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["METRICS", "MetricDoc"]


@dataclass(frozen=True)
class MetricDoc:
    """One metric: the metric set it belongs to, its unit ("1" for a ratio or a count, "text" for
    words) and what it measures."""

    metric_set: str
    unit: str
    definition: str


def _set(metric_set: str, rows: dict[str, tuple[str, str]]) -> dict[str, MetricDoc]:
    return {name: MetricDoc(metric_set, unit, text) for name, (unit, text) in rows.items()}


METRICS: dict[str, MetricDoc] = {
    **_set(
        "circles",
        {
            "path_rms_error_m": (
                "m",
                "RMS distance of the tip from where the hand wants it, while the operator draws "
                "(from the end of the speed ramp; clinical runs: across the pressing direction, "
                "over the measurement window)",
            ),
            "hand_force_rms_N": (
                "N",
                "RMS magnitude of the hand's true force on the handle (clinical runs: on the "
                "probe, from the hand taking it to the end; freehand the weight included)",
            ),
            "filter_lag_ms": (
                "ms",
                "how far the filtered hand force trails the held raw measurement at the circle's "
                "frequency; negative is a lead (the seed's lag added by the filter)",
            ),
            "estimate_lag_ms": (
                "ms",
                "how far the filtered estimate trails the true hand force (sensor latency, "
                "packets and filter together)",
            ),
            "estimate_rms_error_N": (
                "N",
                "RMS magnitude of the filtered estimate minus the true hand force",
            ),
            "velocity_hf_rms_m_s": (
                "m/s",
                "RMS of the tip's velocity above 4 times the circle's frequency (zero-phase "
                "high-pass): jitter and any oscillation of the loop",
            ),
            "velocity_hf_late_rms_m_s": (
                "m/s",
                "the same over the last whole circle only: whether an oscillation lasts to the end",
            ),
        },
    ),
    **_set(
        "static_noise",
        {
            "noise_max_abs_raw_N": (
                "N",
                "per base axis, the largest |hand-force estimate − true hand force| of the raw "
                "(aligned, compensated, held) packets, once the estimator is ready",
            ),
            "noise_max_abs_filtered_N": ("N", "the same for the filtered estimate"),
            "noise_attenuation": ("1", "per base axis, raw over filtered"),
            "rest_motion_m": (
                "m",
                "how far the untouched tip moved in that window: noise past the deadband",
            ),
        },
    ),
    **_set(
        "gravity_calibration",
        {
            "poses": ("1", "static poses the sequencer held"),
            "packets_per_pose_min": ("1", "the fewest FT-150 packets averaged at one pose"),
            "mass_kg": ("kg", "the tool's mass identified by eq. 4-8 from the pose averages"),
            "com_m": ("m", "the tool's centre of mass identified, x, y, z in the sensor frame S"),
            "mass_error_pct": ("%", "signed error of the identified mass against the simulated"),
            "com_error_mm": ("mm", "distance of the identified centre of mass from the simulated"),
            "residual_rms_before_N": (
                "N",
                "per sensor axis, RMS of the pose-averaged force with the bias removed",
            ),
            "residual_rms_after_N": ("N", "the same with the identified weight model removed too"),
            "residual_rms_before_Nm": ("N·m", "the torque's, bias removed"),
            "residual_rms_after_Nm": ("N·m", "the torque's, weight model removed too"),
        },
    ),
    **_set(
        "contact_scan",
        {
            "contact_losses": ("1", "times the tip left the phantom after the first touch"),
            "contact_force_mean_N": (
                "N",
                "mean of the phantom's force along the pressing direction (contact scans: from "
                "2 s after the first touch; clinical runs: over the measurement window)",
            ),
            "contact_force_std_N": ("N", "its standard deviation over the same window"),
            "max_bounce_m": ("m", "the highest the tip rose above the surface after the touch"),
            "orientation_drift_deg": (
                "deg",
                "the largest angle the probe turned from its orientation at the first touch",
            ),
        },
    ),
    **_set(
        "probe_data",
        {
            "probe_samples": ("1", "probe packets during the probe check with the hand off"),
            "probe_raw_correlation": (
                "1",
                "per axis of P, correlation of the rebiased probe reading with the compensated "
                "wrist force (the reference)",
            ),
            "probe_raw_rms_N": ("N", "per axis of P, RMS error of that reading"),
            "probe_corrected_correlation": (
                "1",
                "per axis of P, correlation of the estimator's corrected probe force",
            ),
            "probe_corrected_rms_N": ("N", "per axis of P, RMS error of the corrected force"),
            "probe_corrected_rms_late_N": ("N", "the same over the second half of the samples"),
        },
    ),
    **_set(
        "release",
        {
            "release_drift_m": ("m", "how far the tip moved after the hand let go"),
            "release_settle_s": ("s", "time from the release until the tip stayed under 1 mm/s"),
        },
    ),
    **_set(
        "teleecho",
        {
            "y_tracking_rms_m": (
                "m",
                "RMS of the tip's distance from the reference along the slide, over the slide",
            ),
            "orientation_error_max_rad": (
                "rad",
                "the largest angle between the tip's orientation and its start orientation",
            ),
        },
    ),
    **_set(
        "clinical",
        {
            "hand_force_peak_N": ("N", "the largest magnitude of the hand's force over the task"),
            "hand_impulse_N_s": ("N·s", "the integral of its magnitude over the task"),
            "jitter_lateral_mm": (
                "mm",
                "RMS of the tip's motion above 2 Hz along the array (x of the probe frame T)",
            ),
            "jitter_axial_mm": ("mm", "the same along the beam (z of T)"),
            "jitter_elevation_mm": ("mm", "the same out of the image plane (y of T)"),
            "jitter_image_mm": ("mm", "the same in the image plane: lateral and axial together"),
            "jitter_rotation_deg": (
                "deg",
                "RMS norm of the orientation's high-passed rotation vector",
            ),
            "task_time_s": (
                "s",
                "from the hand taking the probe until the task's goal first held for 0.5 s",
            ),
            "recovery_time_s": (
                "s",
                "from the patient's move away until the contact force is back at 0.8 of its level "
                "before (0 if the contact was kept)",
            ),
            "recovery_peak_N": ("N", "the largest contact force from the move's start to the end"),
            "hold_s": ("s", "how long the robot held the contact (the HOLDING flag)"),
            "hold_contact_force_std_N": (
                "N",
                "std of the phantom's force while the robot held with the hand off the handle, "
                "from 1 s after the let-go",
            ),
            "hold_contact_force_change_N": (
                "N",
                "how far the hold moved that force from its level before the let-go (signed)",
            ),
            "hold_contact_losses": ("1", "times the tip left the phantom while the robot held"),
            "handbacks": ("1", "touches of the handle that handed the probe back"),
            "handback_jump_m": (
                "m",
                "the farthest the tip moved from where it was during a hand-back's blend",
            ),
            "handback_unasked_m": (
                "m",
                "the part of that motion across the pressing direction the hand did not ask for",
            ),
        },
    ),
    **_set(
        "every run with a controller",
        {
            "controller_flags": (
                "text",
                "the status flags the controller raised once the estimator was ready, in words "
                "(`ok` if none)",
            ),
            "controller_stop_s": ("s", "how long it commanded a stop then"),
        },
    ),
    **_set(
        "every run",
        {
            "wall_s": ("s", "wall-clock time of the stepping"),
            "realtime_factor": ("1", "simulated seconds over wall-clock seconds of the stepping"),
        },
    ),
}
"""Metric name -> its set, unit and definition; a name shared by two sets is defined once, by the
first (the definition says where the clinical set measures it differently)."""
