"""The plots a person looks at after a run, one set per kind of scenario (seed 000, Fig. 16-21).

Figures are drawn with matplotlib's Agg backend (no display needed) and returned as PNG bytes, so
the caller decides where and how (atomically) they are written.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable

import numpy as np

from hoh_cosim.cosim.recording import Recording
from hoh_cosim.cosim.report import Report
from hoh_cosim.cosim.scenario import (
    TELEECHO_ARMS,
    TELEECHO_CONTROLLERS,
    ComponentSpec,
    Scenario,
)

__all__ = ["gravity_residual_figure", "png", "pyplot", "render_plots"]

AXES = ("x", "y", "z")


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def png(fig) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    pyplot().close(fig)
    return buffer.getvalue()


def _get(rec: Recording, spec: ComponentSpec | None, port: str) -> np.ndarray | None:
    if spec is None or f"{spec.name}.{port}" not in rec:
        return None
    return rec[f"{spec.name}.{port}"]


def _circles(scenario: Scenario, rec: Recording, report: Report) -> dict[str, bytes]:
    plt = pyplot()
    op = scenario.component_of_kind("operator")
    plant = scenario.component_of_kind("plant")
    est = scenario.component_of_kind("estimator")
    out: dict[str, bytes] = {}
    p, ref = _get(rec, plant, "p_BT_B"), _get(rec, op, "p_ref_B")
    if p is not None and ref is not None and op is not None:
        i, j = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}[op.params.plane]
        active = rec.time >= op.params.start_s
        fig, ax = plt.subplots(figsize=(5.5, 5.5))
        ax.plot(1e3 * ref[active, i], 1e3 * ref[active, j], "k--", lw=1, label="hand's reference")
        ax.plot(1e3 * p[active, i], 1e3 * p[active, j], lw=1, label="probe tip")
        ax.set_xlabel(f"{AXES[i]} [mm]")
        ax.set_ylabel(f"{AXES[j]} [mm]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"path, RMS error {_fmt(report.metrics.get('path_rms_error_m'), 1e3, 'mm')}")
        ax.legend(loc="best")
        fig.tight_layout()
        out["path.png"] = png(fig)
    hand, raw, filt = (
        _get(rec, op, "F_hand_B"),
        _get(rec, est, "F_hand_meas_B"),
        _get(rec, est, "F_hand_B"),
    )
    if hand is not None and raw is not None and filt is not None and op is not None:
        # one second in the middle of the drawing, like the seed's Fig. 20
        mid = 0.5 * (op.params.start_s + op.params.ramp_s + rec.time[-1])
        window = (rec.time >= mid - 0.5) & (rec.time <= mid + 0.5)
        fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 7))
        for k, ax in enumerate(axes):
            t = rec.time[window]
            ax.plot(t, hand[window, k], "k--", lw=1, label="true hand force")
            ax.plot(t, raw[window, k], lw=0.8, drawstyle="steps-post", label="measured (held)")
            ax.plot(t, filt[window, k], lw=1.2, label="filtered")
            ax.set_ylabel(f"F_hand {AXES[k]} [N]")
        axes[-1].set_xlabel("time [s]")
        axes[0].legend(loc="upper right", fontsize=8)
        axes[0].set_title(
            f"hand force in B; filter lag {_fmt(report.metrics.get('filter_lag_ms'), 1, 'ms')}"
        )
        fig.tight_layout()
        out["hand_force.png"] = png(fig)
    out.update(_command(scenario, rec))
    return out


def _command(scenario: Scenario, rec: Recording) -> dict[str, bytes]:
    ctl = scenario.component_of_kind("controller")
    plant = scenario.component_of_kind("plant")
    command, actual = _get(rec, ctl, "twist_B"), _get(rec, plant, "twist_B")
    if command is None or actual is None:
        return {}
    plt = pyplot()
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 6))
    for k, ax in enumerate(axes):
        ax.plot(rec.time, 1e3 * command[:, k], lw=0.8, label="commanded")
        ax.plot(rec.time, 1e3 * actual[:, k], lw=0.8, label="actual")
        ax.set_ylabel(f"v {AXES[k]} [mm/s]")
    axes[-1].set_xlabel("time [s]")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title("tip velocity in B")
    fig.tight_layout()
    return {"velocity.png": png(fig)}


def _static_noise(scenario: Scenario, rec: Recording, report: Report) -> dict[str, bytes]:
    est = scenario.component_of_kind("estimator")
    raw, filt = _get(rec, est, "F_hand_meas_B"), _get(rec, est, "F_hand_B")
    if raw is None or filt is None:
        return {}
    plt = pyplot()
    ready = rec[f"{est.name}.ready"][:, 0] > 0.5
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 7))
    raw_max = report.metrics.get("noise_max_abs_raw_N") or [math.nan] * 3
    filt_max = report.metrics.get("noise_max_abs_filtered_N") or [math.nan] * 3
    for k, ax in enumerate(axes):
        ax.plot(rec.time[ready], raw[ready, k], lw=0.6, label=f"raw, max {raw_max[k]:.2f} N")
        ax.plot(rec.time[ready], filt[ready, k], lw=0.9, label=f"filtered, max {filt_max[k]:.2f} N")
        ax.set_ylabel(f"F_hand {AXES[k]} [N]")
        ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title("hand force estimate with nobody touching (seed Fig. 18)")
    fig.tight_layout()
    return {"noise.png": png(fig)}


def _gravity_calibration(scenario: Scenario, rec: Recording, report: Report) -> dict[str, bytes]:
    cal = report.data.get("calibration")
    if cal is None:
        return {}
    R_BS, wrench = report.data["poses"]
    g_B = scenario.component_of_kind("plant").params.g_B
    return {"gravity_residuals.png": png(gravity_residual_figure(cal, R_BS, wrench, g_B))}


def gravity_residual_figure(cal, R_BS: np.ndarray, wrench: np.ndarray, g_B: np.ndarray, note=""):
    """Seed Fig. 16: per pose, each wrench axis with the bias removed and with the weight model
    removed too."""
    from hoh_cosim.control.gravity import GravityModel

    model = GravityModel(cal.tool, g_B)
    before = wrench - cal.bias
    after = before - np.array([model.weight_S(R) for R in R_BS])
    plt = pyplot()
    fig, axes = plt.subplots(2, 3, sharex=True, figsize=(11, 6))
    labels = ("F_x [N]", "F_y [N]", "F_z [N]", "τ_x [N·m]", "τ_y [N·m]", "τ_z [N·m]")
    pose = np.arange(1, len(R_BS) + 1)
    for k, ax in enumerate(axes.reshape(-1)):
        ax.bar(pose - 0.2, before[:, k], 0.4, label="bias removed")
        ax.bar(pose + 0.2, after[:, k], 0.4, label="weight removed too")
        ax.set_ylabel(labels[k])
    for ax in axes[-1]:
        ax.set_xlabel("pose")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(
        f"gravity compensation per pose (seed Fig. 16){note}: m = {cal.mass_kg:.4f} kg, "
        f"p_SC = {np.round(1e3 * cal.com_m, 2).tolist()} mm"
    )
    fig.tight_layout()
    return fig


def _contact_scan(scenario: Scenario, rec: Recording, report: Report) -> dict[str, bytes]:
    op = scenario.component_of_kind("operator")
    plant = scenario.component_of_kind("plant")
    contact, depth = _get(rec, plant, "F_contact_B"), _get(rec, plant, "penetration")
    hand = _get(rec, op, "F_hand_B")
    if contact is None or depth is None or hand is None:
        return {}
    d = op.params.press_direction_B
    plt = pyplot()
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
    axes[0].plot(rec.time, -contact @ d, lw=1, label="phantom on the probe")
    axes[0].plot(rec.time, hand @ d, lw=1, label="hand, along the press")
    axes[0].axhline(op.params.target_force_N, color="k", ls="--", lw=0.8, label="target")
    axes[0].set_ylabel("force [N]")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title(
        f"contact: mean {_fmt(report.metrics.get('contact_force_mean_N'), 1, 'N')}, "
        f"std {_fmt(report.metrics.get('contact_force_std_N'), 1, 'N')}, "
        f"{report.metrics.get('contact_losses')} losses"
    )
    axes[1].plot(rec.time, 1e3 * depth[:, 0], lw=1)
    axes[1].axhline(0.0, color="k", lw=0.5)
    axes[1].set_ylabel("penetration [mm]")
    axes[1].set_xlabel("time [s]")
    fig.tight_layout()
    return {"contact.png": png(fig), **_command(scenario, rec)}


def _release(scenario: Scenario, rec: Recording, report: Report) -> dict[str, bytes]:
    op = scenario.component_of_kind("operator")
    plant = scenario.component_of_kind("plant")
    p, v, hand = _get(rec, plant, "p_BT_B"), _get(rec, plant, "twist_B"), _get(rec, op, "F_hand_B")
    if p is None or v is None or hand is None:
        return {}
    plt = pyplot()
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 7))
    axes[0].plot(rec.time, hand, lw=1)
    axes[0].set_ylabel("hand force [N]")
    axes[0].legend(["x", "y", "z"], fontsize=8, loc="upper right")
    axes[1].plot(rec.time, 1e3 * np.linalg.norm(v[:, :3], axis=1), lw=1)
    axes[1].set_ylabel("tip speed [mm/s]")
    axes[2].plot(rec.time, 1e3 * (p - p[0]), lw=1)
    axes[2].set_ylabel("tip displacement [mm]")
    axes[2].set_xlabel("time [s]")
    axes[0].set_title(
        f"release: drift {_fmt(report.metrics.get('release_drift_m'), 1e3, 'mm')}, "
        f"settles in {_fmt(report.metrics.get('release_settle_s'), 1, 's')}"
    )
    fig.tight_layout()
    return {"release.png": png(fig)}


def _teleecho(scenario: Scenario, rec: Recording, report: Report) -> dict[str, bytes]:
    """Seed 001's Fig. 13: pose error and its norms, joint torques (the UR5: its speedL command),
    and the contact force."""
    plant = scenario.component_of_kinds(TELEECHO_ARMS)
    ctl = scenario.component_of_kinds(TELEECHO_CONTROLLERS)
    error, norm = _get(rec, ctl, "pose_error"), _get(rec, ctl, "pose_error_norm")
    contact, depth = _get(rec, plant, "F_contact_B"), _get(rec, plant, "penetration")
    if error is None or norm is None or contact is None or depth is None:
        return {}
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, sharex=True, figsize=(11, 7))
    t = rec.time
    axes[0, 0].plot(t, 1e3 * error[:, :3], lw=1)
    axes[0, 0].set_ylabel("position error [mm]")
    axes[0, 0].legend(["x", "y", "z"], fontsize=8, loc="upper right")
    axes[1, 0].plot(t, np.degrees(error[:, 3:]), lw=1)
    axes[1, 0].set_ylabel("orientation error [°]")
    axes[1, 0].legend(["roll", "pitch", "yaw"], fontsize=8, loc="upper right")
    axes[0, 1].plot(t, 1e3 * norm[:, 0], lw=1, label="‖position‖ [mm]")
    axes[0, 1].plot(t, np.degrees(norm[:, 1]), lw=1, label="‖orientation‖ [°]")
    axes[0, 1].set_ylabel("pose error norms")
    axes[0, 1].legend(fontsize=8, loc="upper right")
    normal = contact @ plant.params.phantom.plane_normal_B
    axes[1, 1].plot(t, normal, lw=1, label="normal force [N]")
    axes[1, 1].plot(t, 1e3 * depth[:, 0], lw=1, label="penetration [mm]")
    axes[1, 1].axhline(0.0, color="k", lw=0.5)
    axes[1, 1].legend(fontsize=8, loc="upper right")
    for ax in axes[1]:
        ax.set_xlabel("time [s]")
    axes[0, 0].set_title(
        f"y tracking RMS {_fmt(report.metrics.get('y_tracking_rms_m'), 1e3, 'mm')}, "
        f"max orientation error {_fmt(report.metrics.get('orientation_error_max_rad'), 57.29578, '°')}"
    )
    axes[1, 1].set_title(
        f"contact {_fmt(report.metrics.get('contact_force_mean_N'), 1, 'N')} "
        f"± {_fmt(report.metrics.get('contact_force_std_N'), 1, 'N')}, "
        f"{report.metrics.get('contact_losses')} losses"
    )
    fig.tight_layout()
    images = {"pose_error.png": png(fig)}

    torques = _get(rec, plant, "tau_J")
    command = _get(rec, ctl, "twist_B")
    fig, ax = plt.subplots(figsize=(8, 4))
    if torques is not None:
        ax.plot(t, torques, lw=0.8)
        ax.set_ylabel("joint torque [N·m]")
        ax.legend([f"τ{i + 1}" for i in range(torques.shape[1])], fontsize=7, ncol=4)
    elif command is not None:
        ax.plot(t, 1e3 * command[:, :3], lw=0.8)
        ax.set_ylabel("speedL command [mm/s]")
        ax.legend(["x", "y", "z"], fontsize=8)
    ax.set_xlabel("time [s]")
    fig.tight_layout()
    images["torques.png" if torques is not None else "command.png"] = png(fig)
    return images


def probe_forces_figure(
    t: np.ndarray, reference: np.ndarray, curves: dict[str, np.ndarray], title: str
):
    """Per axis of the probe sensor's frame, the wrist's reference and the probe's readings (the
    seed's Fig. 6, 14 and 15: blue the wrist, red the raw probe, gold the network)."""
    colours = {"raw": "tab:red", "network": "goldenrod", "online": "tab:green"}
    colours["corrected"] = colours["online"]
    plt = pyplot()
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
    for j, ax in enumerate(axes):
        ax.plot(t, reference[:, j], color="tab:blue", lw=1.2, label="wrist (reference)")
        for label, values in curves.items():
            ax.plot(t, values[:, j], color=colours.get(label), lw=0.9, label=label)
        ax.set_ylabel(f"F_{'xyz'[j]} in P [N]")
    axes[0].legend(loc="upper right", fontsize=8, ncol=len(curves) + 1)
    axes[0].set_title(title)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    return fig


def _probe_data(scenario: Scenario, rec: Recording, report: Report) -> dict[str, bytes]:
    s = report.data.get("probe_samples")
    if s is None or len(s.t) == 0:
        return {}
    fig = probe_forces_figure(
        s.t,
        s.reference,
        {"raw": s.m, "corrected": s.corrected},
        f"probe pushes: RMS error raw {_fmt_axes(report.metrics.get('probe_raw_rms_N'))}, "
        f"corrected {_fmt_axes(report.metrics.get('probe_corrected_rms_N'))}",
    )
    return {"probe_forces.png": png(fig)}


def _fmt_axes(values: list[float] | None) -> str:
    return "n/a" if values is None else "/".join(f"{v:.2f}" for v in values) + " N"


def _fmt(value: float | None, scale: float, unit: str) -> str:
    return "n/a" if value is None else f"{scale * value:.3g} {unit}"


def _no_plots(scenario: Scenario, rec: Recording, report: Report) -> dict[str, bytes]:
    """The 'none' set: no plots."""
    return {}


# One entry per metric set of `METRIC_SETS` (scenario.py), which a unit test checks.
_PLOTS: dict[str, Callable[[Scenario, Recording, Report], dict[str, bytes]]] = {
    "none": _no_plots,
    "circles": _circles,
    "static_noise": _static_noise,
    "gravity_calibration": _gravity_calibration,
    "contact_scan": _contact_scan,
    "release": _release,
    "teleecho": _teleecho,
    "probe_data": _probe_data,
}


def render_plots(scenario: Scenario, rec: Recording, report: Report) -> dict[str, bytes]:
    """PNG file name -> contents, for the scenario's metric set (none for 'none')."""
    return _PLOTS[scenario.metrics](scenario, rec, report)
