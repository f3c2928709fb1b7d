"""The plots a person looks at after a run, one set per kind of scenario (seed 000, Fig. 16-21).

Every figure's title says the time window it shows ("t = 16.5–17.5 s of 30 s") and the frame its
vectors are expressed in: B the robot's base, S the wrist sensor, P the probe sensor, d the desired
tip pose (seed 001), the plane and viewing direction for a path. Every axis has its unit. Legends sit
in a margin right of the data, never on it. A commanded signal is drawn black and dashed over the
solid, coloured actual one, and their difference has a panel of its own. Metrics are quoted by their
`summary.json` names; the hand-force figure defines the sign of its lags in a note under the plot.

Speed (a 30 s circles run has 30 001 rows per signal): figures are matplotlib `Figure`s on the Agg
canvas directly, without pyplot or a layout engine (the margins are fixed in inches, so nothing is
drawn twice to measure text), and a long series is drawn through `minmax_indices`: at most
`MAX_POINTS` samples per line, each bucket's minimum and maximum kept, so noise peaks stay where they
are and the picture cannot be told from the one with every sample. matplotlib is imported when the
first figure is made, so `import hoh_cosim` stays light. Figures are returned as PNG bytes; the
caller decides where and how (atomically) they are written.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from hoh_cosim.cosim.recording import Recording
from hoh_cosim.cosim.report import CONTACT_SETTLE_S, SETTLE_SPEED_M_S, Report
from hoh_cosim.cosim.scenario import (
    TELEECHO_ARMS,
    TELEECHO_CONTROLLERS,
    ComponentSpec,
    Scenario,
)
from hoh_cosim.errors import ConfigError
from plant_models.operator import PLANES

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "MAX_POINTS",
    "figures",
    "gravity_residual_figure",
    "minmax_indices",
    "png",
    "probe_forces_figure",
    "pyplot",
    "render_plots",
]

AXES = ("x", "y", "z")
COLOURS = ("tab:blue", "tab:orange", "tab:green")  # x, y, z
MAX_POINTS = 4000
"""Most samples drawn per line: three minimum-maximum pairs per pixel column of a 6.4 in panel."""
DPI = 100

# The fixed layout, in inches: no layout engine measures text at draw time.
_LEFT = 0.85  # y tick labels and the y label
_RIGHT = 0.25
_LEGEND_W = 2.1  # the legend margin right of the panels: 25 characters at 8 pt
_BOTTOM = 0.5  # x tick labels and the x label
_TOP_PAD = 0.1
_TITLE_LINE = 0.19  # one line of the 9.5 pt title
_NOTE_LINE = 0.16  # one line of an 8 pt note under the panels
_HGAP = 0.18  # between panels that share the time axis
_WGAP = 0.8  # between columns: the right column's y labels
_TITLE_PT, _LABEL_PT, _TICK_PT, _LEGEND_PT = 9.5, 9, 8, 8


def pyplot():
    """matplotlib.pyplot on the Agg backend, for callers that build their own figures with it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def png(fig: Figure) -> bytes:
    """The figure as PNG bytes; a pyplot figure is closed too (pyplot holds on to it otherwise)."""
    buffer = io.BytesIO()
    # zlib level 3 instead of 6: a third less encoding time for about 5 % more bytes
    fig.savefig(buffer, format="png", dpi=DPI, pil_kwargs={"compress_level": 3})
    if fig.canvas.manager is not None:
        pyplot().close(fig)
    return buffer.getvalue()


def minmax_indices(y: np.ndarray, max_points: int = MAX_POINTS) -> np.ndarray:
    """Which samples of `y` ((n,) or (n, k)) to draw: at most `max_points`, sorted, the first and
    the last, and the minimum and the maximum of every column in each of equal buckets of samples,
    so a noisy series keeps its envelope and its extremes (NaN samples are never chosen over
    numbers). With k columns the indices are shared (a 2-D path keeps its extremes in x and in y).
    """
    y = np.asarray(y, dtype=np.float64)
    if y.ndim == 1:
        y = y[:, None]
    n, k = y.shape
    if max_points < 4 * k + 2:
        raise ConfigError(f"max_points: expected >= {4 * k + 2} for {k} columns, got {max_points}")
    if n <= max_points:
        return np.arange(n)
    # at most `buckets` full buckets and one partial one, two samples per column each, plus the ends
    buckets = (max_points - 2) // (2 * k) - 1
    size = -(-n // buckets)
    full = n // size * size
    lo = np.where(np.isnan(y), np.inf, y)
    hi = np.where(np.isnan(y), -np.inf, y)
    starts = np.arange(0, full, size)[:, None]
    picks = [
        starts + np.argmin(lo[:full].reshape(-1, size, k), axis=1),
        starts + np.argmax(hi[:full].reshape(-1, size, k), axis=1),
    ]
    if full < n:
        picks += [full + np.argmin(lo[full:], axis=0), full + np.argmax(hi[full:], axis=0)]
    return np.unique(np.concatenate([np.ravel(p) for p in picks] + [np.array([0, n - 1])]))


def _line(ax: Axes, t: np.ndarray, y: np.ndarray, *args: Any, **kwargs: Any) -> None:
    """`ax.plot(t, y)` of one series, decimated by `minmax_indices`."""
    rows = minmax_indices(y)
    ax.plot(t[rows], y[rows], *args, **kwargs)


def _canvas_figure(width: float, height: float) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


def _panels(
    rows: int,
    cols: int = 1,
    *,
    title: str,
    panel: tuple[float, float] = (6.4, 1.55),
    legend: bool = True,
    note: str = "",
    sharex: bool | str = True,
) -> tuple[Figure, np.ndarray]:
    """A figure of rows x cols panels (width, height in inches each), the title above them at the
    left, room for legends on the right of every column when `legend`, and `note` under them."""
    pw, ph = panel
    title_h = _TOP_PAD + _TITLE_LINE * (title.count("\n") + 1) + 0.08
    note_lines = note.count("\n") + 1 if note else 0
    bottom = _BOTTOM + _NOTE_LINE * note_lines + (0.08 if note else 0.0)
    right = _LEGEND_W if legend else _RIGHT
    wgap = _WGAP + (_LEGEND_W if legend and cols > 1 else 0.0)
    hgap = _HGAP if sharex else _BOTTOM + 0.15
    width = _LEFT + cols * pw + (cols - 1) * wgap + right
    height = title_h + rows * ph + (rows - 1) * hgap + bottom
    from matplotlib.ticker import MaxNLocator

    fig = _canvas_figure(width, height)
    axes = fig.subplots(
        rows,
        cols,
        sharex=sharex,
        squeeze=False,
        gridspec_kw={
            "left": _LEFT / width,
            "right": 1.0 - right / width,
            "bottom": bottom / height,
            "top": 1.0 - title_h / height,
            "hspace": hgap / ph,
            "wspace": wgap / pw,
        },
    )
    for ax in axes.flat:
        # a tick costs a dozen artists: five on a y axis read as well as the default nine
        ax.yaxis.set_major_locator(MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10]))
        ax.tick_params(labelsize=_TICK_PT)
        ax.grid(True, lw=0.4, color="0.88")
        ax.set_axisbelow(True)
    fig.suptitle(
        title,
        x=_LEFT / width,
        y=1.0 - _TOP_PAD / height,
        ha="left",
        va="top",
        fontsize=_TITLE_PT,
        linespacing=1.3,
    )
    if note:
        fig.text(_LEFT / width, 0.06 / height, note, ha="left", va="bottom", fontsize=_LEGEND_PT)
    return fig, axes


def _legend(ax: Axes, *args: Any, **kwargs: Any) -> None:
    """A legend in the margin right of `ax`, its top level with the axes' top (none if empty)."""
    if not args and not ax.get_legend_handles_labels()[0]:
        return
    kwargs.setdefault("fontsize", _LEGEND_PT)
    ax.legend(
        *args,
        loc="upper left",
        bbox_to_anchor=(1.0, 1.0),
        borderaxespad=0.6,
        frameon=False,
        handlelength=2.4,
        **kwargs,
    )


def _label(ax: Axes, text: str) -> None:
    ax.set_ylabel(text, fontsize=_LABEL_PT)


def _time_axis(axes: np.ndarray, rec: Recording, t0: float | None = None, t1: float | None = None):
    t0 = rec.time[0] if t0 is None else t0
    t1 = rec.time[-1] if t1 is None else t1
    axes.flat[0].set_xlim(t0, t1)
    for ax in np.atleast_2d(axes)[-1]:
        ax.set_xlabel("time t [s]", fontsize=_LABEL_PT)


def _window(rec: Recording, t0: float | None = None, t1: float | None = None) -> str:
    """'t = 16.5–17.5 s of 30 s', or '… (whole run)' for all of it."""
    start, end = float(rec.time[0]), float(rec.time[-1])
    t0 = start if t0 is None else t0
    t1 = end if t1 is None else t1
    whole = " (whole run)" if math.isclose(t0, start) and math.isclose(t1, end) else ""
    return f"t = {t0:.1f}–{t1:.1f} s of {end:g} s{whole}"


def _at_least(ax: Axes, magnitude: np.ndarray, span: float) -> None:
    """Show at least ±span: an error that is rounding noise (1e-13°) then reads as zero."""
    if not np.nanmax(np.abs(magnitude), initial=0.0) >= span:
        ax.set_ylim(-span, span)


def _get(rec: Recording, spec: ComponentSpec | None, port: str) -> np.ndarray | None:
    if spec is None or f"{spec.name}.{port}" not in rec:
        return None
    return rec[f"{spec.name}.{port}"]


def _fmt(value: float | None, scale: float, unit: str, signed: bool = False) -> str:
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{scale * value:{'+' if signed else ''}.3g} {unit}".replace("-", "−")


def _fmt_axes(values: list[float] | None) -> str:
    return "n/a" if values is None else "/".join(f"{v:.2f}" for v in values) + " N"


def _vector(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:g}" for x in np.asarray(v, dtype=float)) + "]"


# ---------------------------------------------------------------------------------------- circles


def _circle_window(op: ComponentSpec, t_end: float) -> tuple[float, float] | None:
    """The circles metrics' window, as `report._circles` takes it: whole periods from the end of the
    speed ramp; None if not one fits."""
    p = op.params
    start = p.start_s + p.ramp_s
    periods = math.floor((t_end - start) / p.period_s + 1e-9)
    return (start, start + periods * p.period_s) if periods >= 1 else None


_VIEWED_FROM = {"xy": "+z", "xz": "−y", "yz": "+x"}  # e_i × e_j, toward the viewer


def _path_figure(
    rec: Recording, report: Report, op: ComponentSpec, plant: ComponentSpec, p, ref
) -> Figure:
    plane = op.params.plane
    i, j = PLANES[plane]
    window = _circle_window(op, float(rec.time[-1]))
    t0, t1 = window if window else (op.params.start_s, float(rec.time[-1]))
    if t0 > t1:  # the run ends before the hand takes the handle: draw all of it
        t0 = 0.0
    what = (
        "whole circles after the speed ramp: the metric's window" if window else "no whole circle"
    )
    fig, axes = _panels(
        1,
        title=(
            f"Probe-tip path in the {AXES[i]}–{AXES[j]} plane of the base frame B, "
            f"seen from {_VIEWED_FROM[plane]}\n"
            f"{_window(rec, t0, t1)} ({what})\n"
            f"path_rms_error_m = {_fmt(report.metrics.get('path_rms_error_m'), 1e3, 'mm')}"
        ),
        panel=(4.6, 4.6),
        sharex=False,
    )
    ax = axes[0, 0]
    rows = np.flatnonzero((rec.time >= t0) & (rec.time <= t1))
    drawn = rows[minmax_indices(p[rows][:, [i, j]])]
    # the reference goes round the same circle again and again: dashes would fill in, a band reads
    reference = rows[minmax_indices(ref[rows][:, [i, j]])]
    ax.plot(
        1e3 * ref[reference, i],
        1e3 * ref[reference, j],
        color="0.75",
        lw=3.5,
        label=f"hand's reference\n({op.name}.p_ref_B)",
    )
    ax.plot(
        1e3 * p[drawn, i],
        1e3 * p[drawn, j],
        color="tab:blue",
        lw=1.1,
        label=f"probe tip\n({plant.name}.p_BT_B)",
    )
    ax.plot(1e3 * p[rows[0], i], 1e3 * p[rows[0], j], "o", color="tab:blue", ms=4)
    ax.plot([], [], "o", color="tab:blue", ms=4, label=f"tip at t = {t0:.1f} s")
    ax.set_xlabel(f"{AXES[i]} in B [mm]", fontsize=_LABEL_PT)
    _label(ax, f"{AXES[j]} in B [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    _legend(ax)
    return fig


_LAG_NOTE = (
    "Lags at the circle frequency ({f:g} Hz), in ms: > 0 late, < 0 ahead. filter_lag_ms: the "
    "filtered estimate behind the measured (held) force;\n"
    "estimate_lag_ms: the filtered estimate behind the true hand force. A negative filter_lag_ms "
    "is a lead: the Kalman filter extrapolates\n"
    "between packets, and the held reading is on average half a packet period old."
)


def _hand_force_figure(rec: Recording, report: Report, op, est, hand, raw, filt) -> Figure:
    t_end = float(rec.time[-1])
    window = _circle_window(op, t_end)
    start = op.params.start_s + op.params.ramp_s
    # one second in the middle of the drawing, like the seed's Fig. 20
    mid = 0.5 * (start + t_end)
    t0, t1 = max(mid - 0.5, float(rec.time[0])), min(mid + 0.5, t_end)
    rows = (rec.time >= t0) & (rec.time <= t1)
    m = report.metrics
    over = f"metrics over t = {window[0]:.1f}–{window[1]:.1f} s" if window else "no metrics"
    fig, axes = _panels(
        3,
        title=(
            "Hand force on the handle, in the base frame B\n"
            f"{_window(rec, t0, t1)} (1 s in the middle of the circles; {over})\n"
            f"filter_lag_ms = {_fmt(m.get('filter_lag_ms'), 1, 'ms', signed=True)}, "
            f"estimate_lag_ms = {_fmt(m.get('estimate_lag_ms'), 1, 'ms', signed=True)}, "
            f"estimate_rms_error_N = {_fmt(m.get('estimate_rms_error_N'), 1, 'N')}"
        ),
        panel=(6.4, 1.75),
        note=_LAG_NOTE.format(f=1.0 / op.params.period_s),
    )
    t = rec.time[rows]
    for k, ax in enumerate(axes[:, 0]):
        ax.plot(
            t,
            raw[rows, k],
            color="tab:blue",
            lw=0.8,
            drawstyle="steps-post",
            label=f"measured, held\n({est.name}.F_hand_meas_B)",
        )
        ax.plot(
            t,
            filt[rows, k],
            color="tab:orange",
            lw=1.6,
            label=f"filtered estimate\n({est.name}.F_hand_B)",
        )
        ax.plot(t, hand[rows, k], "k--", lw=1.1, label=f"true hand force\n({op.name}.F_hand_B)")
        _label(ax, f"F_hand {AXES[k]} [N]")
    _legend(axes[0, 0])
    _time_axis(axes, rec, t0, t1)
    return fig


def _circles(scenario: Scenario, rec: Recording, report: Report) -> dict[str, Figure]:
    op = scenario.component_of_kind("operator")
    plant = scenario.component_of_kind("plant")
    est = scenario.component_of_kind("estimator")
    out: dict[str, Figure] = {}
    p, ref = _get(rec, plant, "p_BT_B"), _get(rec, op, "p_ref_B")
    if p is not None and ref is not None and op is not None:
        out["path.png"] = _path_figure(rec, report, op, plant, p, ref)
    hand, raw, filt = (
        _get(rec, op, "F_hand_B"),
        _get(rec, est, "F_hand_meas_B"),
        _get(rec, est, "F_hand_B"),
    )
    if hand is not None and raw is not None and filt is not None and op is not None:
        out["hand_force.png"] = _hand_force_figure(rec, report, op, est, hand, raw, filt)
    out.update(_command(scenario, rec))
    return out


# --------------------------------------------------------------------------------------- velocity


def _velocity_figure(
    rec: Recording,
    command: np.ndarray,
    actual: np.ndarray | None,
    names: tuple[str, str],
    what: str = "Probe-tip velocity",
) -> Figure:
    """Per axis of B the commanded (dashed black) and the actual (solid) linear velocity, and their
    difference in a panel of its own."""
    both = actual is not None
    title = (
        f"{what}, commanded ({names[0]}, black dashed)"
        + (f" and actual ({names[1]}, solid)" if both else "")
        + f", in the base frame B\n{_window(rec)}"
        + ("; the difference includes the command's delay to the robot" if both else "")
    )
    fig, axes = _panels(4 if both else 3, title=title, panel=(6.4, 1.35))
    t = rec.time
    for k in range(3):
        ax = axes[k, 0]
        if both:
            _line(ax, t, 1e3 * actual[:, k], color=COLOURS[k], lw=1.8, label="actual")
        _line(ax, t, 1e3 * command[:, k], "k--", lw=0.9, label="commanded")
        _label(ax, f"v_{AXES[k]} [mm/s]")
        _legend(ax)
    if both:
        ax = axes[3, 0]
        for k in range(3):
            diff = 1e3 * (actual[:, k] - command[:, k])
            _line(ax, t, diff, color=COLOURS[k], lw=0.8, label=AXES[k])
        _label(ax, "actual − cmd\n[mm/s]")
        _legend(ax, title="actual − commanded", title_fontsize=_LEGEND_PT)
    _time_axis(axes, rec)
    return fig


def _command(scenario: Scenario, rec: Recording, name: str = "velocity.png") -> dict[str, Figure]:
    ctl = scenario.component_of_kind("controller")
    plant = scenario.component_of_kind("plant")
    command, actual = _get(rec, ctl, "twist_B"), _get(rec, plant, "twist_B")
    if command is None or actual is None:
        return {}
    names = (f"{ctl.name}.twist_B", f"{plant.name}.twist_B")
    return {name: _velocity_figure(rec, command, actual, names)}


# ----------------------------------------------------------------------------------- static noise


def _static_noise(scenario: Scenario, rec: Recording, report: Report) -> dict[str, Figure]:
    est = scenario.component_of_kind("estimator")
    raw, filt = _get(rec, est, "F_hand_meas_B"), _get(rec, est, "F_hand_B")
    if raw is None or filt is None:
        return {}
    ready = rec[f"{est.name}.ready"][:, 0] > 0.5
    if not ready.any():
        return {}
    first = float(rec.time[np.argmax(ready)])
    counted = min(first + 1.0, float(rec.time[-1]))  # the report skips the filters' start-up
    raw_max = report.metrics.get("noise_max_abs_raw_N") or [math.nan] * 3
    filt_max = report.metrics.get("noise_max_abs_filtered_N") or [math.nan] * 3
    attenuation = report.metrics.get("noise_attenuation") or [None] * 3
    fig, axes = _panels(
        3,
        title=(
            "Hand-force estimate with nobody touching (seed Fig. 18), in the base frame B\n"
            f"{_window(rec, first, float(rec.time[-1]))} (from the end of the rebias); "
            f"noise_max_abs_*_N over t = {counted:.1f}–{rec.time[-1]:.1f} s (grey: start-up, "
            "not counted)"
        ),
    )
    t = rec.time[ready]
    for k, ax in enumerate(axes[:, 0]):
        ax.axvspan(first, counted, color="0.9", lw=0)
        _line(ax, t, raw[ready, k], color="tab:blue", lw=0.6, label=f"raw, max {raw_max[k]:.2f} N")
        _line(
            ax,
            t,
            filt[ready, k],
            color="tab:orange",
            lw=1.1,
            label=f"filtered, max {filt_max[k]:.2f} N",
        )
        if attenuation[k] is not None:
            ax.plot([], [], " ", label=f"attenuation ×{attenuation[k]:.2f}")
        _label(ax, f"F_hand {AXES[k]} [N]")
        _legend(ax)
    _time_axis(axes, rec, first)
    return {"noise.png": fig}


# ---------------------------------------------------------------------------- gravity calibration


def _gravity_calibration(scenario: Scenario, rec: Recording, report: Report) -> dict[str, Figure]:
    cal = report.data.get("calibration")
    if cal is None:
        return {}
    R_BS, wrench = report.data["poses"]
    g_B = scenario.component_of_kind("plant").params.g_B
    seq = scenario.component_of_kind("sequencer")
    holding = _get(rec, seq, "holding")
    window = _window(rec)
    if holding is not None and (holding[:, 0] > 0.5).any():
        held = rec.time[holding[:, 0] > 0.5]
        window = _window(rec, float(held[0]), float(held[-1]))
    fig = gravity_residual_figure(cal, R_BS, wrench, g_B, window=f"poses held over {window}")
    return {"gravity_residuals.png": fig}


def gravity_residual_figure(
    cal, R_BS: np.ndarray, wrench: np.ndarray, g_B: np.ndarray, note: str = "", window: str = ""
) -> Figure:
    """Seed Fig. 16: per pose, each wrench axis (in the wrist sensor's frame S) with the bias
    removed and with the weight model removed too. `note` follows the figure's name, `window`
    (which poses or times) starts the second title line."""
    from hoh_cosim.control.gravity import GravityModel

    model = GravityModel(cal.tool, g_B)
    before = wrench - cal.bias
    after = before - np.array([model.weight_S(R) for R in R_BS])
    n = len(R_BS)
    fig, axes = _panels(
        2,
        3,
        title=(
            f"Gravity compensation per pose (seed Fig. 16){note}: the mean wrist wrench of each "
            "pose, in the sensor frame S\n"
            + (f"{window}; " if window else "")
            + f"{n} poses; m = {cal.mass_kg:.4f} kg, p_SC = "
            f"{np.round(1e3 * cal.com_m, 2).tolist()} mm in S\n"
            f"force residual RMS x/y/z: {_fmt_axes(cal.residual_rms_before[:3].tolist())} with "
            f"the bias removed, {_fmt_axes(cal.residual_rms_after[:3].tolist())} with the weight "
            "removed too"
        ),
        panel=(3.0, 2.3),
        legend=False,
    )
    labels = [
        f"{q} in S [{unit}]"
        for q, unit in zip(
            ("F_x", "F_y", "F_z", "τ_x", "τ_y", "τ_z"), ("N",) * 3 + ("N·m",) * 3, strict=True
        )
    ]
    pose = np.arange(1, n + 1)
    for k, ax in enumerate(axes.reshape(-1)):
        ax.bar(pose - 0.2, before[:, k], 0.4, color="tab:blue", label="bias removed")
        ax.bar(pose + 0.2, after[:, k], 0.4, color="tab:orange", label="weight removed too")
        ax.axhline(0.0, color="k", lw=0.5)
        _label(ax, labels[k])
    for ax in axes[-1]:
        ax.set_xlabel("pose number", fontsize=_LABEL_PT)
    handles, names = axes[0, 0].get_legend_handles_labels()
    # above the panels, right of the title's first line would collide: below the title instead
    fig.legend(
        handles,
        names,
        loc="upper right",
        bbox_to_anchor=(1.0 - _RIGHT / fig.get_figwidth(), 1.0 - 0.08 / fig.get_figheight()),
        ncol=1,
        fontsize=_LEGEND_PT,
        frameon=False,
    )
    return fig


# ----------------------------------------------------------------------------------- contact scan


def _contact_scan(scenario: Scenario, rec: Recording, report: Report) -> dict[str, Figure]:
    op = scenario.component_of_kind("operator")
    plant = scenario.component_of_kind("plant")
    contact, depth = _get(rec, plant, "F_contact_B"), _get(rec, plant, "penetration")
    hand = _get(rec, op, "F_hand_B")
    if contact is None or depth is None or hand is None:
        return {}
    u = op.params.press_direction_B
    touching = depth[:, 0] > 0.0
    settled = float(rec.time[np.argmax(touching)]) + CONTACT_SETTLE_S if touching.any() else None
    m = report.metrics
    stats = (
        f"statistics from t = {settled:.1f} s (dotted: first touch + {CONTACT_SETTLE_S:g} s)"
        if settled is not None
        else "the probe never touched the phantom"
    )
    fig, axes = _panels(
        2,
        title=(
            f"Pressing on the phantom, forces along the press direction u = {_vector(u)} of the "
            f"base frame B\n{_window(rec)}; " + stats + "\n"
            f"contact_force_mean_N = {_fmt(m.get('contact_force_mean_N'), 1, 'N')}, "
            f"contact_force_std_N = {_fmt(m.get('contact_force_std_N'), 1, 'N')}, "
            f"contact_losses = {m.get('contact_losses')}, "
            f"max_bounce_m = {_fmt(m.get('max_bounce_m'), 1e3, 'mm')}"
        ),
        panel=(6.4, 2.0),
    )
    t = rec.time
    ax = axes[0, 0]
    _line(ax, t, -contact @ u, color="tab:blue", lw=1.2, label="phantom on the probe")
    _line(ax, t, hand @ u, color="tab:orange", lw=1.2, label="hand, along u")
    ax.axhline(op.params.target_force_N, color="k", ls="--", lw=0.8, label="operator's target")
    _label(ax, "force along u [N]")
    ax = axes[1, 0]
    _line(ax, t, 1e3 * depth[:, 0], color="tab:blue", lw=1.2, label="tip depth")
    ax.axhline(0.0, color="k", lw=0.5, label="phantom surface")
    _label(ax, "penetration [mm]\n(> 0 in the phantom)")
    for ax in axes[:, 0]:
        if settled is not None:
            ax.axvline(settled, color="0.4", ls=":", lw=1.0)
        _legend(ax)
    _time_axis(axes, rec)
    return {"contact.png": fig, **_command(scenario, rec)}


# ---------------------------------------------------------------------------------------- release


def _release(scenario: Scenario, rec: Recording, report: Report) -> dict[str, Figure]:
    op = scenario.component_of_kind("operator")
    plant = scenario.component_of_kind("plant")
    p, v, hand = _get(rec, plant, "p_BT_B"), _get(rec, plant, "twist_B"), _get(rec, op, "F_hand_B")
    if p is None or v is None or hand is None:
        return {}
    on = _get(rec, op, "hand_on")
    falls = np.flatnonzero(on[:-1, 0] > 0.5) if on is not None else np.array([], dtype=int)
    falls = falls[on[falls + 1, 0] <= 0.5] if len(falls) else falls
    k = int(falls[-1]) + 1 if len(falls) else None  # the first row with the hand off, as the report
    m = report.metrics
    settle = m.get("release_settle_s")
    when = f"hand lets go at t = {rec.time[k]:.2f} s (dotted)" if k is not None else "no release"
    fig, axes = _panels(
        4,
        title=(
            "Push and release: hand force, tip speed and displacement in the base frame B\n"
            f"{_window(rec)}; {when}\n"
            f"release_drift_m = {_fmt(m.get('release_drift_m'), 1e3, 'mm')}, "
            f"release_settle_s = {_fmt(settle, 1, 's')} "
            f"(speed under {1e3 * SETTLE_SPEED_M_S:g} mm/s from then on)"
        ),
        panel=(6.4, 1.45),
    )
    t = rec.time
    for j in range(3):
        _line(axes[0, 0], t, hand[:, j], color=COLOURS[j], lw=1.1, label=AXES[j])
    _label(axes[0, 0], "hand force [N]")
    _line(axes[1, 0], t, 1e3 * np.linalg.norm(v[:, :3], axis=1), color="k", lw=1.0, label="‖v‖")
    axes[1, 0].axhline(1e3 * SETTLE_SPEED_M_S, color="0.4", ls="--", lw=0.8, label="settled below")
    _label(axes[1, 0], "tip speed [mm/s]")
    for j in range(3):
        _line(axes[2, 0], t, 1e3 * (p[:, j] - p[0, j]), color=COLOURS[j], lw=1.1, label=AXES[j])
    _label(axes[2, 0], "tip displacement\nfrom t = 0 [mm]")
    if k is not None:
        drift = np.full(len(t), np.nan)
        drift[k:] = 1e3 * np.linalg.norm(p[k:] - p[k], axis=1)
        _line(axes[3, 0], t, drift, color="k", lw=1.1, label="‖p − p(release)‖")
        for ax in axes[:, 0]:
            ax.axvline(t[k], color="0.4", ls=":", lw=1.0)
            if settle is not None:
                ax.axvline(t[k] + settle, color="tab:red", ls=":", lw=1.0)
        axes[3, 0].plot([], [], color="tab:red", ls=":", lw=1.0, label="settled")
    else:
        axes[3, 0].text(
            0.5, 0.5, "the hand never lets go", ha="center", transform=axes[3, 0].transAxes
        )
    _label(axes[3, 0], "drift after\nrelease [mm]")
    for ax in axes[:, 0]:
        _legend(ax)
    _time_axis(axes, rec)
    return {"release.png": fig}


# --------------------------------------------------------------------------------------- teleecho


def _teleecho(scenario: Scenario, rec: Recording, report: Report) -> dict[str, Figure]:
    """Seed 001's Fig. 13: the pose error and its norms, the slide, the contact; then the joint
    torques (the Panda) or the speedL command (the UR5)."""
    plant = scenario.component_of_kinds(TELEECHO_ARMS)
    ctl = scenario.component_of_kinds(TELEECHO_CONTROLLERS)
    error, norm = _get(rec, ctl, "pose_error"), _get(rec, ctl, "pose_error_norm")
    contact, depth = _get(rec, plant, "F_contact_B"), _get(rec, plant, "penetration")
    if error is None or norm is None or contact is None or depth is None:
        return {}
    task = ctl.params.task
    m = report.metrics
    ref, p = _get(rec, ctl, "p_ref_B"), _get(rec, plant, "p_BT_B")
    slide = ref is not None and p is not None
    tilt = m.get("orientation_error_max_rad")
    fig, axes = _panels(
        5 if slide else 4,
        title=(
            "Tele-echography slide (seed 001, Fig. 13): the tip's pose error in the desired "
            "frame d,\nits position and the phantom's force in the base frame B\n"
            f"{_window(rec)}; approach from t = {task.approach_start_s:g} s, slide from "
            f"t = {task.slide_start_s:g} s (dotted)\n"
            f"y_tracking_rms_m = {_fmt(m.get('y_tracking_rms_m'), 1e3, 'mm')} (during the slide), "
            f"orientation_error_max_rad = {_fmt(tilt, 1, 'rad')} "
            f"({'n/a' if tilt is None else f'{math.degrees(tilt):.2f}°'} from the start's)\n"
            f"contact_force_mean_N = {_fmt(m.get('contact_force_mean_N'), 1, 'N')}, "
            f"contact_force_std_N = {_fmt(m.get('contact_force_std_N'), 1, 'N')}, "
            f"contact_losses = {m.get('contact_losses')}"
        ),
        panel=(6.4, 1.4),
    )
    t = rec.time
    rows = iter(axes[:, 0])
    ax = next(rows)
    for j in range(3):
        _line(ax, t, 1e3 * error[:, j], color=COLOURS[j], lw=1.0, label=AXES[j])
    _line(ax, t, 1e3 * norm[:, 0], "k", lw=0.8, label="‖·‖")
    _label(ax, "tip − desired\nposition, in d [mm]")
    ax = next(rows)
    for j, name in enumerate(("roll", "pitch", "yaw")):
        _line(ax, t, np.degrees(error[:, 3 + j]), color=COLOURS[j], lw=1.0, label=name)
    _line(ax, t, np.degrees(norm[:, 1]), "k", lw=0.8, label="‖·‖")
    _label(ax, "tip vs desired\nroll-pitch-yaw [°]")
    _at_least(ax, np.degrees(norm[:, 1]), 0.1)
    if slide:
        ax = next(rows)
        axis = np.asarray(task.axis_B)
        _line(ax, t, 1e3 * (p @ axis), color="tab:blue", lw=1.8, label="tip")
        # before its first step the controller's outputs are zeros, not a reference at the origin
        along = np.where(np.any(ref != 0.0, axis=1), ref @ axis, np.nan)
        _line(ax, t, 1e3 * along, "k--", lw=0.9, label="reference")
        _label(ax, f"along {_vector(axis)}\nin B [mm]")
    ax = next(rows)
    normal = contact @ plant.params.phantom.plane_normal_B
    _line(ax, t, normal, color="tab:blue", lw=1.1, label="along the normal")
    _label(ax, "phantom force [N]")
    ax = next(rows)
    _line(ax, t, 1e3 * depth[:, 0], color="tab:blue", lw=1.1, label="tip depth")
    ax.axhline(0.0, color="k", lw=0.5, label="surface")
    _label(ax, "penetration [mm]\n(> 0 in the phantom)")
    for ax in axes[:, 0]:
        ax.axvline(task.approach_start_s, color="0.4", ls=":", lw=1.0)
        ax.axvline(task.slide_start_s, color="0.4", ls=":", lw=1.0)
        _legend(ax)
    _time_axis(axes, rec)
    images = {"pose_error.png": fig}

    torques = _get(rec, plant, "tau_J")
    command = _get(rec, ctl, "twist_B")
    if torques is not None:
        fig, axes = _panels(
            1,
            title=(
                f"Joint torques applied, {plant.name}.tau_J (the clamped command plus gravity), "
                "in joint space\n"
                f"{_window(rec)}"
            ),
            panel=(6.4, 3.0),
        )
        for j in range(torques.shape[1]):
            _line(axes[0, 0], t, torques[:, j], lw=0.9, label=f"joint {j + 1}")
        _label(axes[0, 0], "τ_J [N·m]")
        _legend(axes[0, 0])
        _time_axis(axes, rec)
        images["torques.png"] = fig
    elif command is not None:
        actual = _get(rec, plant, "twist_B")
        names = (f"{ctl.name}.twist_B", f"{plant.name}.twist_B")
        images["command.png"] = _velocity_figure(rec, command, actual, names, "speedL tip velocity")
    return images


# ------------------------------------------------------------------------------------- probe data


def probe_forces_figure(
    t: np.ndarray, reference: np.ndarray, curves: dict[str, np.ndarray], title: str
) -> Figure:
    """Per axis of the probe sensor's frame P, the wrist's reference and the probe's readings (the
    seed's Fig. 6, 14 and 15: blue the wrist, red the raw probe, gold the network). `title` is the
    first line; the second says the frame and the time window."""
    colours = {"raw": "tab:red", "network": "goldenrod", "online": "tab:green"}
    colours["corrected"] = colours["online"]
    window = f"t = {t[0]:.1f}–{t[-1]:.1f} s, {len(t)} probe packets" if len(t) else "no samples"
    fig, axes = _panels(
        3,
        title=f"{title}\nforces on the probe tip, per axis of the probe sensor frame P; {window}",
        panel=(6.6, 1.75),
    )
    for j, ax in enumerate(axes[:, 0]):
        _line(ax, t, reference[:, j], color="tab:blue", lw=1.3, label="wrist (reference)")
        for label, values in curves.items():
            _line(ax, t, values[:, j], color=colours.get(label), lw=0.9, label=label)
        _label(ax, f"F_{AXES[j]} in P [N]")
    _legend(axes[0, 0])
    if len(t):
        axes[0, 0].set_xlim(t[0], t[-1])
    axes[-1, 0].set_xlabel("time t [s]", fontsize=_LABEL_PT)
    return fig


def _probe_data(scenario: Scenario, rec: Recording, report: Report) -> dict[str, Figure]:
    s = report.data.get("probe_samples")
    if s is None or len(s.t) == 0:
        return {}
    m = report.metrics
    fig = probe_forces_figure(
        s.t,
        s.reference,
        {"raw": s.m, "corrected": s.corrected},
        f"Pushes on the probe tip during the probe check, of a {rec.time[-1]:g} s run\n"
        f"probe_raw_rms_N = {_fmt_axes(m.get('probe_raw_rms_N'))}, "
        f"probe_corrected_rms_N = {_fmt_axes(m.get('probe_corrected_rms_N'))} (x/y/z)",
    )
    return {"probe_forces.png": fig}


def _clinical(scenario: Scenario, rec: Recording, report: Report) -> dict[str, Figure]:
    """One clinical task run: the contact force with the breathing beside it, the hand's force,
    and the tip's jitter in the probe's frame."""
    from hoh_cosim.cosim.clinical import ARM_KINDS, JITTER_HZ, measurement_window
    from hoh_cosim.cosim.metrics import high_passed

    op = scenario.component_of_kind("operator")
    arm = scenario.component_of_kinds(ARM_KINDS)
    breathing = scenario.component_of_kind("breathing")
    contact, hand, tip = (
        _get(rec, arm, "F_contact_B"),
        _get(rec, op, "F_hand_B"),
        _get(rec, arm, "p_BT_B"),
    )
    R = _get(rec, arm, "R_BT")
    if contact is None or hand is None or tip is None or R is None:
        return {}
    m = report.metrics
    u = op.params.press_direction_B
    window, _ = measurement_window(scenario, rec)
    mode = "freehand" if arm.kind.name == "freehand" else "on the robot"
    fig, axes = _panels(
        3,
        title=(
            f"{op.params.task} task {mode}: forces along the press direction u = {_vector(u)}, "
            f"hand force, tip jitter\n{_window(rec)}; statistics after the dotted line\n"
            f"hand_force_rms_N = {_fmt(m.get('hand_force_rms_N'), 1, 'N')}, "
            f"contact_force_std_N = {_fmt(m.get('contact_force_std_N'), 1, 'N')}, "
            f"contact_losses = {m.get('contact_losses')}, "
            f"jitter_image_mm = {_fmt(m.get('jitter_image_mm'), 1e3, 'µm')}"
        ),
        panel=(6.4, 1.7),
    )
    t = rec.time
    ax = axes[0, 0]
    _line(ax, t, -contact @ u, color="tab:blue", lw=1.1, label="phantom on the probe")
    ax.axhline(op.params.target_force_N, color="k", ls="--", lw=0.8, label="target")
    _label(ax, "contact force\nalong u [N]")
    offset = _get(rec, breathing, "offset_m")
    if offset is not None:
        twin = ax.twinx()
        _line(twin, t, 1e3 * offset[:, 0], color="0.6", lw=0.9)
        twin.set_ylabel("breathing [mm]", fontsize=_LABEL_PT, color="0.45")
        twin.tick_params(labelsize=_TICK_PT)
        ax.plot([], [], color="0.6", lw=0.9, label="breathing (right)")
    _line(axes[1, 0], t, np.linalg.norm(hand, axis=1), color="tab:orange", lw=1.0, label="‖F_hand‖")
    _label(axes[1, 0], "hand force [N]")
    if window.sum() > 2 * round(1.0 / scenario.dt_s):
        e = np.full(len(t), np.nan)
        e_B = high_passed(tip[window], JITTER_HZ, scenario.dt_s)
        e_T = np.einsum("nji,nj->ni", R[window].reshape(-1, 3, 3), e_B)
        for j, (k, name) in enumerate(((0, "lateral"), (2, "axial"), (1, "elevation"))):
            e[window] = 1e3 * e_T[:, k]
            _line(axes[2, 0], t, e.copy(), color=COLOURS[j], lw=0.8, label=name)
    _label(axes[2, 0], f"tip above {JITTER_HZ:g} Hz\nin the probe frame [mm]")
    if window.any():
        for ax in axes[:, 0]:
            ax.axvline(t[np.argmax(window)], color="0.4", ls=":", lw=1.0)
    for ax in axes[:, 0]:
        _legend(ax)
    _time_axis(axes, rec)
    return {"clinical.png": fig}


def _no_plots(scenario: Scenario, rec: Recording, report: Report) -> dict[str, Figure]:
    """The 'none' set: no plots."""
    return {}


# One entry per metric set of `METRIC_SETS` (scenario.py), which a unit test checks.
_PLOTS: dict[str, Callable[[Scenario, Recording, Report], dict[str, Figure]]] = {
    "none": _no_plots,
    "circles": _circles,
    "static_noise": _static_noise,
    "gravity_calibration": _gravity_calibration,
    "contact_scan": _contact_scan,
    "release": _release,
    "teleecho": _teleecho,
    "probe_data": _probe_data,
    "clinical": _clinical,
}


def figures(scenario: Scenario, rec: Recording, report: Report) -> dict[str, Figure]:
    """PNG file name -> matplotlib Figure (on the Agg canvas), for the scenario's metric set."""
    return _PLOTS[scenario.metrics](scenario, rec, report)


def render_plots(scenario: Scenario, rec: Recording, report: Report) -> dict[str, bytes]:
    """PNG file name -> contents, for the scenario's metric set (none for 'none')."""
    return {name: png(fig) for name, fig in figures(scenario, rec, report).items()}
