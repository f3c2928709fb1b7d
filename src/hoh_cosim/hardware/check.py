"""`hoh-cosim hw check`'s measurements and verdicts: pure functions over what the sensors delivered.

The seed lost weeks to sensors that streamed plausible numbers and were wrong (seed 000, 3.B.2: a
load cell in constant saturation, an FSE103 whose housing redirected force; 5.A). The commissioning
check (`hoh_cosim.hardware.check_run` moves the robot and records) gives this module a
`CheckRecord`: every sample of every stream with its time of receipt, and the check's windows (rest
at the start, the static poses, rest at the end, the pushes on the probe's tip) with the wrist's
mean orientation in each. Per sensor it measures and judges:

    rate and regularity   samples per second against the rig's claimed rate (the estimator's
                          packet period), the longest gap and the share of gaps over 3 periods
    noise at rest         the standard deviation per axis against the seed's noise (σ = max/3.5)
    zero drift            the rest mean at the end less the one at the start
    known loads           the wrist: the tool's weight across the poses against the gravity model
                          (eq. 4-5), the change from the start pose fitted by a 3x3 gain matrix A
                          (A = I for a healthy sensor: its diagonal is the axes' gains and signs,
                          its off-diagonal the frame); the probe sensor: the pushes on the tip
                          seen by the wrist, turned into P by the rig's R_SP (eq. 2), against what
                          the probe sensor reported
    frame                 the rotation that best turns the wrist's pushes into the probe's
                          (Kabsch), its angle and whether it is a reflection (an axis flipped)
    linearity             what a fit leaves: linear, and the online map's features (φ(m) of
                          `control.probe_correction`): more than the map can absorb is a housing
                          the probe check cannot correct
    range and saturation  the largest reading against the sensor's range

Thresholds are set from the sensors' specifications and the models' noise, each with its reason
beside it, so that a healthy sensor passes with a wide margin and a planted fault fails with one
(docs/decisions/0071-hw-check.md gives the margins measured). A probe sensor plugs in with one
entry of `PROBE_CHECKS`: a function of its `ProbeEvidence` and the rig's claims to a verdict.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hoh_cosim.control.cycle import PROBE_SENSORS
from hoh_cosim.control.estimator import (
    FSE103_NOISE_MAX,
    FT150_NOISE_MAX_S,
    FT150_TORQUE_NOISE_MAX_S,
    NOISE_MAX_PER_SIGMA,
)
from hoh_cosim.control.gravity import ToolParams, tool_weight_wrench_S
from hoh_cosim.control.loadcell import SEED_CHAIN
from hoh_cosim.control.probe_correction import features
from hoh_cosim.control.vectors import GRAVITY_B, Rot3, Vec
from hoh_cosim.errors import ConfigError

__all__ = [
    "FT150_RANGE",
    "PROBE_CHECKS",
    "PROBE_SENSORS",
    "SENSORS",
    "CheckRecord",
    "Claims",
    "Finding",
    "LoadCellSpec",
    "ProbeEvidence",
    "SensorVerdict",
    "Stream",
    "Window",
    "check_fse103",
    "check_ft150",
    "check_loadcell",
    "frame_fit",
    "gravity_gains",
    "judge",
    "map_residual_N",
    "push_pairs",
    "rate_figures",
    "report",
    "session_refusal",
]

SENSORS = ("ft150", "fse103", "loadcell")
"""The sensors a verdict names (`--override`)."""

FT150_RANGE = np.array([150.0] * 3 + [15.0] * 3)
"""[N, N·m] The Robotiq FT-150's measuring range per axis (its data sheet: ±150 N, ±15 N·m)."""

AXES_FT = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
AXES_P = ("x", "y", "z")

# --- thresholds, each from a specification or a model ------------------------------------------
RATE_TOLERANCE = 0.2
"""Measured rate within ±20 % of the claimed: the estimator's Kalman gains assume the claimed
period, and at 20 % slow the gaps stay under the runner's 3-period stale limit with room."""
LATE_GAPS_MAX = 0.05
"""At most 5 % of the gaps over 3 claimed periods (each such gap zeroes a session's command);
a healthy stream has none but those a loaded machine makes, a stream at a quarter of its claimed
rate has all of them."""
NOISE_HIGH = 3.0
"""Noise at rest up to 3x the seed's σ (max/3.5, `control.estimator`): above, the deadband the
admittance law needs (seed eq. 10) grows threefold."""
NOISE_LOW = 0.1
"""... and at least a tenth of it: a channel flatter than that has stopped sensing (a dead gauge
reads its quantum or nothing)."""
DRIFT_LIMIT = np.array([0.5] * 3 + [0.05] * 3)
"""[N, N·m] Zero drift over the check: a quarter of the rebias tolerance (`RebiasConfig`, 2 N and
0.2 N·m), since a session runs ten times longer than the check. The FT-150 model drifts
0.005 N/√s: 0.03 N in a 40 s check."""
GAIN_TOLERANCE = 0.4
"""An axis's gain against the gravity model within 1 ± 0.4, a cross gain within ±0.4: the seed's
compensation was good to ±1 N (5.B, cable drag) on the 3.3 N a 45° tilt moves a lateral axis. A
flipped axis has -1, a dead one 0."""
FIT_RESIDUAL_N = 1.0
"""[N] The wrist's weight fit may leave 1 N RMS: the seed's compensation accuracy (5.B)."""
EXCITED = 20.0
"""An axis counts as excited by the poses when the gravity model moves it by 20 standard errors of a
pose mean; the wrist's z torque is not (the tool's centre of mass sits on the axis)."""
PUSH_MIN_N = 3.0
"""[N] The pushes must reach 3 N at the wrist (the emulated hand's reach 2-15 N)."""
PUSH_SAMPLE_N = 1.0
"""[N] Samples with the wrist's push above 1 N (3x the wrist's noise) enter the frame fit."""
FRAME_ANGLE_MAX_DEG = 40.0
"""The probe sensor's frame within 40° of eq. 2: the seed's housing turns a push by about 20° per
σ of its cross gains (σ 0.25, `HousingParams`: atan(0.25·√2)), 40° is two of them; a sensor
mounted a quarter turn off the probe's axis is 90° off (less the housing's own turn)."""
PLANAR = 0.1
"""Pushes whose third singular value is under a tenth of the first span a plane, not space."""
PUSH_GAIN = (0.5, 1.5)
"""The probe's push over the wrist's within 0.5-1.5: the housing's gains (σ 0.15) and stiffening."""
MAP_RESIDUAL_N = 2.0
"""[N] RMS the online map's features may leave: no map of m corrects the housing's play (its
hysteresis), which leaves about the play's width per axis; at the seed's widest play, 0.8 N on
every axis (`HousingParams.play_N`), that is √3 · 0.8 ≈ 1.4 N, and the two streams aligned by their
receipt times add up to a push's slope (24 N/s at most) times the FSE103's 20 ms period, 0.5 N.
More is a housing the online map (`control.probe_correction`, reference σ 0.5 N) cannot follow."""
SMOOTH_S = 0.1
"""[s] The wrist's reference for the pushes is averaged over 0.1 s: its noise (0.3 N per axis, the
seed's) falls fourfold and a 2 s push changes by under 0.01 N from it."""
REDIRECTION_ADVICE = 0.1
"""A housing whose linear fit is further than 10 % from the identity needs the probe check."""


# --- what was recorded --------------------------------------------------------------------------
@dataclass(frozen=True)
class Stream:
    """What one sensor delivered: receipt times [s] (monotonic), values (n x axes)."""

    t_s: Vec
    values: Vec
    bad_frames: int = 0

    @staticmethod
    def of(samples: Sequence[Any], bad_frames: int = 0, axes: int = 3) -> Stream:
        """From `hardware.streams.Sample`s."""
        t = np.array([s.received_s for s in samples], dtype=float)
        v = np.array([s.values for s in samples], dtype=float).reshape(len(samples), axes)
        return Stream(t, v, bad_frames)

    def between(self, start_s: float, end_s: float) -> Vec:
        return self.values[(self.t_s >= start_s) & (self.t_s <= end_s)]


@dataclass(frozen=True)
class Window:
    """A stretch of the check: `kind` rest, pushes or pose, from `start_s` to `end_s` (monotonic)
    with the wrist sensor's mean orientation R_BS."""

    kind: str
    start_s: float
    end_s: float
    R_BS: Rot3


@dataclass(frozen=True)
class CheckRecord:
    ft: Stream
    probe: Stream | None
    windows: tuple[Window, ...]

    def of_kind(self, kind: str) -> list[Window]:
        return [w for w in self.windows if w.kind == kind]


@dataclass(frozen=True)
class Claims:
    """What the rig says about itself: the config's rates and frames, the calibrated tool."""

    ft_rate_hz: float
    probe_rate_hz: float
    R_SP: Rot3
    tool: ToolParams
    g_B: Vec = field(default_factory=lambda: GRAVITY_B.copy())


# --- verdicts -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Finding:
    """One measurement: `what` (rate, noise, ...), ok or not, its figure against the expected."""

    what: str
    ok: bool
    text: str
    value: float | list[float] | None = None
    limit: Any = None
    judged: bool = True  # False: its reference failed, so it says nothing (and fails nothing)


@dataclass
class SensorVerdict:
    sensor: str  # ft150, fse103, loadcell
    label: str  # for people
    findings: list[Finding]
    advice: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(f.ok for f in self.findings if f.judged)

    def line(self) -> str:
        """One line: ok with the key figures, or every cause with its figure."""
        if self.ok:
            key = [f.text for f in self.findings if f.what in _KEY_FIGURES and f.judged]
            text = f"{self.label}: ok (" + "; ".join(key) + ")"
            text += "".join(f"; {f.text}" for f in self.findings if not f.judged)
        else:
            causes = [f.text for f in self.findings if f.judged and not f.ok]
            text = f"{self.label}: FAIL " + "; ".join(causes)
        return text + "".join(f"; {a}" for a in self.advice)

    def as_dict(self) -> dict[str, Any]:
        return {
            "ok": self.ok,
            "line": self.line(),
            "advice": self.advice,
            "findings": {
                f.what: {
                    "ok": f.ok,
                    "judged": f.judged,
                    "text": f.text,
                    "value": f.value,
                    "limit": f.limit,
                }
                for f in self.findings
            },
        }


_KEY_FIGURES = ("rate", "noise", "axis signs", "frame", "linearity")
"""The figures an ok line shows; a failing line shows every cause."""


def _floats(v: Vec) -> list[float]:
    return [float(x) for x in np.asarray(v).reshape(-1)]


def _bounded(what: str, ok: bool, text: str, value: Any, limit: Any) -> Finding:
    if isinstance(value, np.ndarray):
        value = _floats(value)
    if isinstance(limit, np.ndarray):
        limit = _floats(limit)
    return Finding(what, bool(ok), text, value, limit)


# --- measurements, shared by every sensor ---------------------------------------------------------
def rate_figures(t_s: Vec, claimed_hz: float) -> dict[str, float]:
    """The rate [Hz] from first to last sample, the longest gap [s], the share of gaps over 3
    claimed periods, and the 99th percentile gap [s]."""
    t = np.asarray(t_s, dtype=float)
    if t.size < 2 or t[-1] <= t[0]:
        return {"rate_hz": 0.0, "longest_gap_s": math.inf, "late": 1.0, "p99_gap_s": math.inf}
    gaps = np.diff(t)
    return {
        "rate_hz": (t.size - 1) / (t[-1] - t[0]),
        "longest_gap_s": float(gaps.max()),
        "late": float(np.mean(gaps > 3.0 / claimed_hz)),
        "p99_gap_s": float(np.percentile(gaps, 99)),
    }


def stream_findings(
    stream: Stream,
    record: CheckRecord,
    claimed_hz: float,
    sigma: Vec,
    axes: Sequence[str],
    unit: Sequence[str],
    drift_limit: Vec,
    *,
    noise_low: bool = True,
) -> list[Finding]:
    """Rate, regularity, noise at rest and zero drift: what every sensor's stream is judged by."""
    out = []
    r = rate_figures(stream.t_s, claimed_hz)
    rate_ok = abs(r["rate_hz"] / claimed_hz - 1.0) <= RATE_TOLERANCE
    out.append(
        _bounded(
            "rate",
            rate_ok,
            f"rate {r['rate_hz']:.1f} Hz against {claimed_hz:g} Hz ±{100 * RATE_TOLERANCE:.0f} %",
            r["rate_hz"],
            [claimed_hz * (1 - RATE_TOLERANCE), claimed_hz * (1 + RATE_TOLERANCE)],
        )
    )
    out.append(
        _bounded(
            "regularity",
            r["late"] <= LATE_GAPS_MAX,
            f"{100 * r['late']:.1f} % of gaps over 3 periods against <= "
            f"{100 * LATE_GAPS_MAX:.0f} % (longest {1e3 * r['longest_gap_s']:.0f} ms)",
            r["late"],
            LATE_GAPS_MAX,
        )
    )
    rests = record.of_kind("rest")
    first = stream.between(rests[0].start_s, rests[0].end_s)
    last = stream.between(rests[-1].start_s, rests[-1].end_s)
    if len(first) < 10 or len(last) < 10:
        out.append(Finding("noise", False, f"only {len(first)} samples at rest (expected >= 10)"))
        return out
    std = first.std(axis=0, ddof=1)
    high, low = NOISE_HIGH * sigma, NOISE_LOW * sigma
    bad = [
        f"{a} {'flat' if s < lo else 'noisy'}: σ {s:.3g} {u} at rest against {lo:.2g}-{hi:.2g} {u}"
        for a, u, s, lo, hi in zip(axes, unit, std, low, high, strict=True)
        if s > hi or (noise_low and s < lo)
    ]
    out.append(
        _bounded(
            "noise",
            not bad,
            "; ".join(bad) or f"noise at rest {np.max(std / sigma):.2f}x the seed's at most",
            std,
            [_floats(low), _floats(high)],
        )
    )
    drift = last.mean(axis=0) - first.mean(axis=0)
    over = [
        f"{a} drifted {d:+.3g} {u} against ±{lim:g} {u}"
        for a, u, d, lim in zip(axes, unit, drift, drift_limit, strict=True)
        if abs(d) > lim
    ]
    elapsed = rests[-1].start_s - rests[0].start_s
    out.append(
        _bounded(
            "drift",
            not over,
            "; ".join(over)
            or f"drift {np.max(np.abs(drift) / drift_limit):.2f}x its limit in {elapsed:.0f} s",
            drift,
            drift_limit,
        )
    )
    return out


# --- the wrist: the tool's weight across the poses -----------------------------------------------
def _pose_means(record: CheckRecord) -> tuple[list[Vec], list[Rot3], list[int]]:
    means, R, counts = [], [], []
    for w in [record.of_kind("rest")[0], *record.of_kind("pose")]:
        v = record.ft.between(w.start_s, w.end_s)
        means.append(v.mean(axis=0) if len(v) else np.full(6, np.nan))
        R.append(w.R_BS)
        counts.append(len(v))
    return means, R, counts


def gravity_gains(record: CheckRecord, claims: Claims) -> dict[str, Any]:
    """The wrist's response to the tool's weight: the change from the start pose of each pose's
    mean against the gravity model's (eq. 4-5, `tool_weight_wrench_S`), as gains.

    Forces: A = argmin Σ‖Δf_meas - A Δf_model‖² over the poses (3x3; I when healthy). Torques: one
    slope per axis, Σ Δτ_meas Δτ_model / Σ Δτ_model², where the poses excite the axis. Returns
    A, the torque slopes (NaN where not excited), the force fit's RMS residual [N] and the
    excitation per axis (the model's RMS change over a pose mean's standard error)."""
    means, R, counts = _pose_means(record)
    model = [tool_weight_wrench_S(r, claims.tool, claims.g_B) for r in R]
    d_meas = np.array([m - means[0] for m in means[1:]])
    d_model = np.array([m - model[0] for m in model[1:]])
    A_T, *_ = np.linalg.lstsq(d_model[:, :3], d_meas[:, :3], rcond=None)
    A = A_T.T
    residual = d_meas[:, :3] - d_model[:, :3] @ A_T
    sigma = np.concatenate([FT150_NOISE_MAX_S, FT150_TORQUE_NOISE_MAX_S]) / NOISE_MAX_PER_SIGMA
    se = sigma * math.sqrt(2.0 / max(1, min(counts)))
    excitation = np.sqrt(np.mean(d_model**2, axis=0)) / se
    slopes = np.full(3, np.nan)
    for i in range(3):
        if excitation[3 + i] >= EXCITED:
            x, y = d_model[:, 3 + i], d_meas[:, 3 + i]
            slopes[i] = float(x @ y / (x @ x))
    return {
        "A": A,
        "torque_slopes": slopes,
        "residual_N": float(np.sqrt(np.mean(residual**2))),
        "excitation": excitation,
    }


def _gain_cause(axis: str, g: float) -> str:
    if g <= -0.5:
        return f"{axis} sign flipped: gain {g:+.2f} against +1 ± {GAIN_TOLERANCE:g}"
    if abs(g) < 0.5:
        return f"{axis} does not respond: gain {g:+.2f} against +1 ± {GAIN_TOLERANCE:g}"
    return f"{axis} gain {g:+.2f} against +1 ± {GAIN_TOLERANCE:g}"


def check_ft150(record: CheckRecord, claims: Claims) -> SensorVerdict:
    """The FT-150's verdict: its stream, its response to the tool's weight, its range."""
    sigma = np.concatenate([FT150_NOISE_MAX_S, FT150_TORQUE_NOISE_MAX_S]) / NOISE_MAX_PER_SIGMA
    units = ("N",) * 3 + ("N·m",) * 3
    findings = stream_findings(
        record.ft, record, claims.ft_rate_hz, sigma, AXES_FT, units, DRIFT_LIMIT
    )
    g = gravity_gains(record, claims)
    A, slopes = g["A"], g["torque_slopes"]
    gains = [*np.diag(A).tolist(), *slopes.tolist()]
    wrong = [
        _gain_cause(a, x)
        for a, x in zip(AXES_FT, gains, strict=True)
        if math.isfinite(x) and abs(x - 1.0) > GAIN_TOLERANCE
    ]
    idle = [a for a, x in zip(AXES_FT, gains, strict=True) if not math.isfinite(x)]
    findings.append(
        _bounded(
            "axis signs",
            not wrong,
            "; ".join(wrong)
            or "gains against the gravity model "
            + " ".join(f"{x:+.2f}" for x in gains if math.isfinite(x))
            + (f" ({', '.join(idle)} not excited by the poses)" if idle else ""),
            [x if math.isfinite(x) else None for x in gains],
            [1.0 - GAIN_TOLERANCE, 1.0 + GAIN_TOLERANCE],
        )
    )
    cross = A - np.diag(np.diag(A))
    i, j = np.unravel_index(int(np.argmax(np.abs(cross))), (3, 3))
    findings.append(
        _bounded(
            "frame",
            abs(cross[i, j]) <= GAIN_TOLERANCE,
            f"cross gain {AXES_FT[j]}->{AXES_FT[i]} {cross[i, j]:+.2f} against ±{GAIN_TOLERANCE:g}",
            float(cross[i, j]),
            GAIN_TOLERANCE,
        )
    )
    findings.append(
        _bounded(
            "linearity",
            g["residual_N"] <= FIT_RESIDUAL_N,
            f"weight fit leaves {g['residual_N']:.2f} N RMS against <= {FIT_RESIDUAL_N:g} N",
            g["residual_N"],
            FIT_RESIDUAL_N,
        )
    )
    findings.append(_range_finding(record.ft.values, FT150_RANGE, AXES_FT))
    return SensorVerdict("ft150", "FT-150", findings)


def _range_finding(values: Vec, full_scale: Vec, axes: Sequence[str]) -> Finding:
    used = np.nanmax(np.abs(values), axis=0) / full_scale
    k = int(np.argmax(used))
    return _bounded(
        "range",
        bool(used[k] < 0.98),
        f"range used {100 * used[k]:.1f} % ({axes[k]})"
        + (" : saturated" if used[k] >= 0.98 else ""),
        used,
        0.98,
    )


# --- the probe sensor: the pushes against the wrist ----------------------------------------------
@dataclass(frozen=True)
class ProbeEvidence:
    """What a probe sensor's check works on: its stream, the record, and the pushes as pairs (the
    wrist's push turned into P, f_ref_P, and the probe's reading m_P, both less their rest mean,
    at the probe's sample times)."""

    stream: Stream
    record: CheckRecord
    f_ref_P: Vec  # (n, 3)
    m_P: Vec  # (n, 3)
    reference_ok: bool = True  # the wrist, the pushes' reference, passed its own check


def push_pairs(record: CheckRecord, R_SP: Rot3) -> tuple[Vec, Vec]:
    """The pushes: the wrist's force less its mean at rest before them, interpolated to the probe's
    sample times and turned into P (f_P = R_SPᵀ f_S), and the probe's reading less its rest mean."""
    assert record.probe is not None
    pushes = record.of_kind("pushes")[0]
    rest = [w for w in record.of_kind("rest") if w.end_s <= pushes.start_s][-1]
    ft, probe = record.ft, record.probe
    f0 = ft.between(rest.start_s, rest.end_s)[:, :3].mean(axis=0)
    m0 = probe.between(rest.start_s, rest.end_s).mean(axis=0)
    inside = (probe.t_s >= pushes.start_s) & (probe.t_s <= pushes.end_s)
    t = probe.t_s[inside]
    smooth = _moving_average(ft.t_s, ft.values[:, :3], SMOOTH_S)
    f_S = np.column_stack([np.interp(t, ft.t_s, smooth[:, i]) for i in range(3)]) - f0
    return f_S @ R_SP, probe.values[inside] - m0


def _moving_average(t_s: Vec, values: Vec, width_s: float) -> Vec:
    """Each sample replaced by the mean of the samples within ±width_s/2 of it."""
    c = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0)])
    lo = np.searchsorted(t_s, t_s - 0.5 * width_s, side="left")
    hi = np.searchsorted(t_s, t_s + 0.5 * width_s, side="right")
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def frame_fit(f_ref_P: Vec, m_P: Vec) -> dict[str, Any]:
    """The rotation Q that best turns the wrist's pushes into the probe's, m ≈ s Q f (Kabsch:
    Q = U diag(1, 1, det(U Vᵀ)) Vᵀ from the SVD U Σ Vᵀ of Σ m fᵀ), its angle [deg] and the scale
    s = Σ m·Qf / Σ |f|²; `reflected` when the best reflection (the last sign the other way) fits
    with under half the rotation's residual: an axis flipped. Pushes that span a plane only fit a
    rotation and its reflection alike, and are not taken for a flip."""
    H = m_P.T @ f_ref_P
    U, _, Vt = np.linalg.svd(H)
    d = 1.0 if np.linalg.det(U @ Vt) > 0.0 else -1.0

    def fit(last: float) -> tuple[Vec, float, float]:
        Q = U @ np.diag([1.0, 1.0, last]) @ Vt
        turned = f_ref_P @ Q.T
        scale = float(np.sum(m_P * turned) / max(np.sum(turned**2), 1e-12))
        return Q, scale, float(np.sqrt(np.mean(np.sum((m_P - scale * turned) ** 2, axis=1))))

    Q, scale, residual = fit(d)
    _, _, mirrored = fit(-d)
    spread = np.linalg.svd(f_ref_P, compute_uv=False)
    angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(Q) - 1.0) / 2.0))))
    return {
        "Q": Q,
        "angle_deg": angle,
        "scale": scale,
        "reflected": mirrored < 0.5 * residual,
        "residual_N": residual,
        "mirrored_residual_N": mirrored,
        "planar": bool(spread[2] < PLANAR * spread[0]),
    }


def map_residual_N(f_ref_P: Vec, m_P: Vec, linear_only: bool = False) -> float:
    """[N] RMS of what a least-squares fit f ≈ Θᵀφ(m) leaves, φ the online map's 7 features
    (`probe_correction.features`), or with `linear_only` the 4 of [m, 1]: the part of the wrist's
    push that no map of that form gives from the probe's reading."""
    phi = np.array([features(m) for m in m_P])
    if linear_only:
        phi = phi[:, [0, 1, 2, 6]]
    theta, *_ = np.linalg.lstsq(phi, f_ref_P, rcond=None)
    return float(np.sqrt(np.mean(np.sum((f_ref_P - phi @ theta) ** 2, axis=1))))


def _push_findings(evidence: ProbeEvidence) -> tuple[list[Finding], np.ndarray]:
    """Whether the pushes came; the samples in which the wrist felt one."""
    f = evidence.f_ref_P
    reach = float(np.max(np.linalg.norm(f, axis=1))) if len(f) else 0.0
    strong = np.linalg.norm(f, axis=1) > PUSH_SAMPLE_N if len(f) else np.zeros(0, bool)
    came = reach >= PUSH_MIN_N and int(strong.sum()) >= 10
    return [
        _bounded(
            "pushes",
            came,
            f"pushes up to {reach:.1f} N at the wrist"
            + ("" if came else f" against >= {PUSH_MIN_N:g} N: push the tip when told"),
            reach,
            PUSH_MIN_N,
        )
    ], strong


def check_fse103(evidence: ProbeEvidence, claims: Claims) -> SensorVerdict:
    """The FSE103's verdict: its stream; the pushes' response, frame and linearity against the
    wrist; the recommendation of the probe check where its housing redirects force (seed 3.B.2)."""
    sigma = FSE103_NOISE_MAX / NOISE_MAX_PER_SIGMA
    findings = stream_findings(
        evidence.stream,
        evidence.record,
        claims.probe_rate_hz,
        sigma,
        AXES_P,
        ("N",) * 3,
        DRIFT_LIMIT[:3],
    )
    pushes, strong = _push_findings(evidence)
    findings += pushes
    verdict = SensorVerdict("fse103", "FSE103", findings)
    if not pushes[0].ok:
        return verdict
    if not evidence.reference_ok:
        findings.append(_unjudged())
        return verdict
    f, m = evidence.f_ref_P[strong], evidence.m_P[strong]
    linear = map_residual_N(evidence.f_ref_P, evidence.m_P, linear_only=True)
    mapped = map_residual_N(evidence.f_ref_P, evidence.m_P)
    findings.append(
        _bounded(
            "linearity",
            mapped <= MAP_RESIDUAL_N,
            f"the online map's fit leaves {mapped:.2f} N RMS against <= {MAP_RESIDUAL_N:g} N "
            f"(linear {linear:.2f} N)"
            + (
                ": the housing is nonlinear beyond what the online map corrects; run the "
                "probe check (preset clinical) and inspect the housing"
                if mapped > MAP_RESIDUAL_N
                else ""
            ),
            [mapped, linear],
            MAP_RESIDUAL_N,
        )
    )
    if mapped > MAP_RESIDUAL_N:  # no frame or gain describes a reading that no map fits
        findings.append(
            Finding(
                "frame",
                True,
                "frame not judged: the reading is no map of the push",
                judged=False,
            )
        )
        return verdict
    fit = frame_fit(f, m)
    lo, hi = PUSH_GAIN
    findings.append(
        _bounded(
            "response",
            lo <= fit["scale"] <= hi,
            f"pushes read at {fit['scale']:.2f} of the wrist's against {lo:g}-{hi:g}"
            + (": no response" if abs(fit["scale"]) < 0.2 else ""),
            fit["scale"],
            list(PUSH_GAIN),
        )
    )
    if fit["reflected"]:
        text = (
            f"axis sign flipped: a reflection fits with {fit['mirrored_residual_N']:.2f} N RMS, "
            f"a rotation with {fit['residual_N']:.2f} N"
        )
    else:
        text = f"frame off eq. 2 by {fit['angle_deg']:.0f}° against <= {FRAME_ANGLE_MAX_DEG:g}°"
    if fit["planar"]:
        text += " (the pushes spanned a plane: a flip across it shows as a turn, or not at all)"
    findings.append(
        _bounded(
            "frame",
            not fit["reflected"] and fit["angle_deg"] <= FRAME_ANGLE_MAX_DEG,
            text,
            fit["angle_deg"],
            FRAME_ANGLE_MAX_DEG,
        )
    )
    redirection = float(np.linalg.norm(_linear_gain(f, m) - np.eye(3), 2))
    if verdict.ok and redirection > REDIRECTION_ADVICE:
        verdict.advice.append(
            f"the housing redirects {100 * redirection:.0f} % of a push: run sessions with the "
            f"probe check (probe_correction online)"
        )
    return verdict


def _unjudged() -> Finding:
    """The pushes' findings when the wrist, their reference, failed: not judged."""
    return Finding(
        "response", True, "pushes not judged: the FT-150, their reference, failed", judged=False
    )


def _linear_gain(f: Vec, m: Vec) -> Vec:
    """G = argmin Σ‖m - G f‖² (3x3)."""
    G_T, *_ = np.linalg.lstsq(f, m, rcond=None)
    return G_T.T


@dataclass(frozen=True)
class LoadCellSpec:
    """What the load cell's check needs of its model (seed 3.B.2, Fig. 8: the Honeywell Model 31
    through an INA125P into an Arduino's 10-bit ADC): newtons of compression to ADC counts, the
    ADC's top count, and the noise at rest [N] the model gives (0 where one count swamps it)."""

    counts_of: Callable[[Vec], Vec]
    adc_max: int = 1023
    noise_N: float = 0.0


SATURATED_SPAN = 0.1
"""A load cell whose counts move by under a tenth of what the wrist's push should give (or by
under 3 counts) is saturated: the seed's moved 1 count (0.005 V of 5 V) under compression."""


def check_loadcell(evidence: ProbeEvidence, claims: Claims, spec: LoadCellSpec) -> SensorVerdict:
    """The load cell's verdict: its stream; whether its counts follow the wrist's push along its
    axis (z of its frame: compression only), or sit saturated (seed 3.B.2, Fig. 9); the gain, sign
    and linearity of the newtons it reports against the wrist's."""
    sigma = np.full(3, max(spec.noise_N, 1e-6))
    findings = stream_findings(
        evidence.stream,
        evidence.record,
        claims.probe_rate_hz,
        sigma,
        AXES_P,
        ("N",) * 3,
        DRIFT_LIMIT[:3],
        noise_low=False,  # a 10-bit ADC at rest may read one count throughout
    )
    if spec.noise_N == 0.0:  # one count swamps the noise: nothing to judge at rest
        findings = [f for f in findings if f.what != "noise"]
    pushes, _ = _push_findings(evidence)
    findings += pushes
    verdict = SensorVerdict("loadcell", "load cell", findings)
    if not pushes[0].ok:
        return verdict
    if not evidence.reference_ok:
        findings.append(_unjudged())
        return verdict
    # compression is the pushes' side of z, whichever sign the driver gives it (eq. 3 turns z_L
    # down the probe); the probe's reading is taken on the same side
    side = 1.0 if float(np.sum(evidence.f_ref_P[:, 2])) >= 0.0 else -1.0
    f_z, m_z = side * evidence.f_ref_P[:, 2], side * evidence.m_P[:, 2]
    reach = float(np.max(f_z))
    expected = float(
        spec.counts_of(np.array([side * reach]))[0] - spec.counts_of(np.array([0.0]))[0]
    )
    counts = spec.counts_of(evidence.stream.values[:, 2])
    span = float(np.ptp(spec.counts_of(side * m_z))) if len(m_z) else 0.0
    at_rail = float(np.mean((counts <= 0.5) | (counts >= spec.adc_max - 0.5)))
    saturated = span < max(3.0, SATURATED_SPAN * abs(expected)) or at_rail > 0.5
    findings.append(
        _bounded(
            "range",
            not saturated,
            (
                f"saturated: pushes of {reach:.1f} N along its axis moved it {span:.0f} counts "
                f"against >= {max(3.0, SATURATED_SPAN * abs(expected)):.0f} "
                f"(expected {abs(expected):.0f}); {100 * at_rail:.0f} % of readings at an ADC rail"
            )
            if saturated
            else f"pushes moved it {span:.0f} counts of {spec.adc_max}",
            span,
            max(3.0, SATURATED_SPAN * abs(expected)),
        )
    )
    if saturated:
        return verdict
    loaded = f_z > PUSH_SAMPLE_N
    x, y = f_z[loaded], m_z[loaded]
    gain = float(x @ y / (x @ x)) if len(x) else 0.0
    lo, hi = PUSH_GAIN
    findings.append(
        _bounded(
            "response",
            lo <= gain <= hi,
            (f"axis sign flipped: gain {gain:+.2f}" if gain < -0.2 else f"gain {gain:+.2f}")
            + f" against {lo:g}-{hi:g} of the wrist's push along its axis",
            gain,
            list(PUSH_GAIN),
        )
    )
    residual = float(np.sqrt(np.mean((y - gain * x) ** 2))) if len(x) else 0.0
    findings.append(
        _bounded(
            "linearity",
            residual <= FIT_RESIDUAL_N,
            f"a line through zero leaves {residual:.2f} N RMS against <= {FIT_RESIDUAL_N:g} N",
            residual,
            FIT_RESIDUAL_N,
        )
    )
    return verdict


ProbeCheck = Callable[[ProbeEvidence, Claims], SensorVerdict]

SEED_LOADCELL = LoadCellSpec(
    counts_of=lambda F_z: SEED_CHAIN.zero_count - SEED_CHAIN.counts_per_N * np.asarray(F_z),
    adc_max=1023,
    noise_N=0.0,  # the model's 2 mV is under half a count (0.064 N): judged by the pushes
)
"""The seed's chain (`control.loadcell.SEED_CHAIN`): its driver reports (0, 0, -compression)."""

PROBE_CHECKS: dict[str, ProbeCheck] = {
    "fse103": check_fse103,
    "loadcell": lambda evidence, claims: check_loadcell(evidence, claims, SEED_LOADCELL),
}
"""Per probe sensor, its check over what its stream delivered."""


# --- the whole check ------------------------------------------------------------------------------
def judge(record: CheckRecord, claims: Claims, probe_sensor: str) -> list[SensorVerdict]:
    """Every sensor's verdict: the wrist's, then the probe sensor's (none: the wrist's only)."""
    verdicts = [check_ft150(record, claims)]
    if probe_sensor != "none":
        if record.probe is None or probe_sensor not in PROBE_CHECKS:
            raise ConfigError(
                f"--probe-sensor: expected one of {', '.join([*PROBE_CHECKS, 'none'])}, "
                f"got {probe_sensor!r}"
            )
        f_ref, m = push_pairs(record, claims.R_SP)
        evidence = ProbeEvidence(record.probe, record, f_ref, m, verdicts[0].ok)
        verdicts.append(PROBE_CHECKS[probe_sensor](evidence, claims))
    return verdicts


def session_refusal(verdicts: Sequence[SensorVerdict], overrides: Sequence[str]) -> list[str]:
    """The failing sensors not overridden by name: a session is refused while any is left. An
    override naming a sensor the check did not judge is refused in one line."""
    names = [v.sensor for v in verdicts]
    for name in overrides:
        if name not in names:
            raise ConfigError(f"--override: expected one of {', '.join(names)}, got {name!r}")
    return [v.sensor for v in verdicts if not v.ok and v.sensor not in overrides]


def report(
    verdicts: Sequence[SensorVerdict], overrides: Sequence[str], about: dict[str, Any]
) -> dict[str, Any]:
    """The JSON report: `about` (how the check ran), per sensor its verdict, the session's."""
    refused = session_refusal(verdicts, overrides)
    return {
        **about,
        "ok": all(v.ok for v in verdicts),
        "sensors": {v.sensor: v.as_dict() for v in verdicts},
        "overrides": list(overrides),
        "session": "refused" if refused else "allowed",
        "refused_by": refused,
    }
