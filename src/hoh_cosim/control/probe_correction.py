"""Probe-force correction: the FSE103 read through a map that each session re-identifies.

The seed (000, 3.B.2, 4.A, 5.A) found that the probe sensor's housing redirects force between axes
with hysteresis, so its reading m is not the contact force f. It trained three multiple-input
single-output networks (Fig. 7: one hidden layer of 20 sigmoid neurons each) on one day's data, got
validation correlations of 0.945, 0.981 and 0.998, and saw the correction fail the next day (Fig. 15)
because the housing had changed. Contact compensation (eq. 11-12) then could not be trusted.

Three corrections, each f̂ = correct(m) in the probe sensor's frame P, after the rebias:

- `none`: f̂ = m.
- `network`: the seed's: three networks, one per axis, each x ↦ w₂ᵀ σ(W₁ x + b₁) + b₂ on the
  standardised reading, σ the logistic function. Trained once (``hoh-cosim probe-correction`` does it
  with scikit-learn's MLPRegressor); here only the forward pass, from the weights as one vector.
- `online`: f̂ = Θᵀ φ(m) with φ(m) = [m, m ⊙ |m| / 10 N, 1] (7 features: the housing's cross-axis
  gains, its stiffening, and what is left of the offset), Θ a 7 x 3 matrix tracked by a Kalman filter
  whose state is Θ, with random-walk process noise (the housing changes slowly and between sessions)
  and the compensated wrist force as the measurement. Each output's own stiffening term gets the
  prior's σ, the cross terms a tenth of it: the few pushes of a check cannot pin nine cross terms
  down, and unpinned quadratic terms extrapolate wildly above the forces the check reached. The wrist sensor is the reference only while
  nothing but the probe is touched: the probe check, a window after the rebias in which the hand is
  off the handle and someone presses the probe tip in several directions (the seed's way of collecting
  its training data, Fig. 6 and 14, done at the start of every session instead of once).

The consistency check (`ContactConsistency`) compares the two sensors while the hand is on the handle.
The hand pushes at the handle H, the contact acts at the tip T, both on the probe's axis: the wrist's
force and torque together give the contact force across that axis without knowing the hand's force,

    τ' = τ_R - p_RH × F = (p_RT - p_RH) × F_contact   ⇒   F_contact,⊥ = (τ' × d) / |d|²,  d = p_RT - p_RH

if the hand puts no torque of its own on the handle (a grip torque τ_g moves it by τ_g / |d|). The
difference from the corrected probe force across the axis, low-passed, is the mismatch; above the
threshold the probe sensor is flagged. The component along the axis is what the hand and the contact
share and cannot be told apart from the wrist alone: only the probe check identifies it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np

from hoh_cosim.control.vectors import Vec, Vec3, as_scalar, as_vector, frozen
from hoh_cosim.errors import ConfigError

__all__ = [
    "CORRECTION_KINDS",
    "FEATURES",
    "HANDLE_S",
    "HIDDEN",
    "NETWORK_SIZE",
    "TIP_S",
    "ContactConsistency",
    "OnlineProbeMap",
    "ProbeCorrection",
    "ProbeCorrectionParams",
    "contact_across_axis",
    "features",
    "map_update",
    "network_forward",
    "pack_network",
]

TIP_S = frozen([0.0, 0.0, -0.200])
"""[m] The probe tip in the wrist sensor's frame S: 200 mm below it, on its -z axis
(`plant_models.tool`)."""
HANDLE_S = frozen([0.0, 0.0, -0.090])
"""[m] Where the hand holds the handle, in S: 90 mm below it, on the probe's axis."""

CorrectionKind = Literal["none", "network", "online"]
CORRECTION_KINDS: tuple[str, ...] = ("none", "network", "online")

HIDDEN = 20
"""Neurons in each network's hidden layer (seed Fig. 7)."""
_PER_AXIS = HIDDEN * 3 + HIDDEN + HIDDEN + 1  # W₁, b₁, w₂, b₂
NETWORK_SIZE = 12 + 3 * _PER_AXIS
"""Length of the network vector: input mean and scale, output mean and scale (3 each), then per axis
W₁ (20 x 3, row by row), b₁ (20), w₂ (20), b₂ (1)."""

FEATURES = 7
"""φ(m) = [m_x, m_y, m_z, m_x|m_x|/10, m_y|m_y|/10, m_z|m_z|/10, 1]."""
_QUADRATIC_SCALE_N = 10.0


def pack_network(
    x_mean: Vec3,
    x_scale: Vec3,
    y_mean: Vec3,
    y_scale: Vec3,
    layers: list[tuple[np.ndarray, np.ndarray, np.ndarray, float]],
) -> Vec:
    """The network vector of three per-axis networks (W₁ 20x3, b₁ 20, w₂ 20, b₂)."""
    parts = [np.asarray(v, dtype=np.float64).reshape(3) for v in (x_mean, x_scale, y_mean, y_scale)]
    if len(layers) != 3:
        raise ConfigError(f"network: expected 3 per-axis networks, got {len(layers)}")
    for W1, b1, w2, b2 in layers:
        parts += [np.asarray(W1).reshape(HIDDEN * 3), np.asarray(b1).reshape(HIDDEN)]
        parts += [np.asarray(w2).reshape(HIDDEN), np.array([float(b2)])]
    return frozen(np.concatenate(parts))


def network_forward(weights: Vec, m: Vec3) -> Vec3:
    """The seed's three networks on the reading m (P frame, rebiased): f̂_i = net_i(m)."""
    x = (np.asarray(m) - weights[0:3]) / weights[3:6]
    out = np.empty(3)
    for i in range(3):
        k = 12 + i * _PER_AXIS
        W1 = weights[k : k + 3 * HIDDEN].reshape(HIDDEN, 3)
        b1 = weights[k + 3 * HIDDEN : k + 4 * HIDDEN]
        w2 = weights[k + 4 * HIDDEN : k + 5 * HIDDEN]
        hidden = 1.0 / (1.0 + np.exp(-(W1 @ x + b1)))
        out[i] = float(w2 @ hidden) + weights[k + 5 * HIDDEN]
    return out * weights[9:12] + weights[6:9]


def features(m: Vec3) -> Vec:
    """φ(m) of the online map."""
    m0, m1, m2 = np.asarray(m, dtype=np.float64).tolist()
    s = _QUADRATIC_SCALE_N
    return np.array([m0, m1, m2, m0 * abs(m0) / s, m1 * abs(m1) / s, m2 * abs(m2) / s, 1.0])


def map_update(
    theta: np.ndarray, P: np.ndarray, phi: Vec, f_ref: Vec3, r: float
) -> tuple[np.ndarray, np.ndarray, Vec3]:
    """One Kalman measurement update of the map Θ (7x3; column i maps φ to output i) with the
    covariances P (3x7x7, one per output) from the reference f_ref for the features φ; returns
    (Θ, P, innovation). Per output i, with its column θᵢ and covariance Pᵢ:

        eᵢ = f_ref,i - θᵢᵀφ,  sᵢ = φᵀPᵢφ + r,  kᵢ = Pᵢφ / sᵢ,  θᵢ ← θᵢ + kᵢ eᵢ,  Pᵢ ← Pᵢ - kᵢ kᵢᵀ sᵢ
    """
    e = np.asarray(f_ref, dtype=np.float64) - theta.T.dot(phi)
    Pphi = P @ phi  # (3, 7)
    s = Pphi.dot(phi) + r  # (3,)
    k = Pphi / s[:, None]
    P = P - k[:, :, None] * k[:, None, :] * s[:, None, None]
    return theta + (k * e[:, None]).T, 0.5 * (P + P.transpose(0, 2, 1)), e


def contact_across_axis(F_S: Vec3, tau_R_S: Vec3, p_RH_S: Vec3, p_RT_S: Vec3) -> Vec3:
    """The contact force across the probe's axis from the wrist's force and torque about R, in S
    (module docstring): the hand at H, the contact at T, no torque of the hand's own."""
    d = np.asarray(p_RT_S, dtype=np.float64) - p_RH_S
    p_RH = _floats(p_RH_S)
    return np.array(_contact_across_axis(F_S, tau_R_S, p_RH, d.tolist(), float(d @ d)))


def _contact_across_axis(
    F_S: Vec3, tau_R_S: Vec3, p_RH_S: list[float], d: list[float], dd: float
) -> tuple[float, float, float]:
    """`contact_across_axis` with d = p_RT - p_RH and dd = d·d given, in floats:
    τ' = τ_R - p_RH × F ;  F_contact,⊥ = (τ' × d) / dd."""
    f0, f1, f2 = _floats(F_S)
    h0, h1, h2 = p_RH_S
    d0, d1, d2 = d
    t0, t1, t2 = _floats(tau_R_S)
    t0, t1, t2 = t0 - (h1 * f2 - h2 * f1), t1 - (h2 * f0 - h0 * f2), t2 - (h0 * f1 - h1 * f0)
    return (t1 * d2 - t2 * d1) / dd, (t2 * d0 - t0 * d2) / dd, (t0 * d1 - t1 * d0) / dd


def _floats(v: Vec3 | Sequence[float]) -> list[float]:
    return np.asarray(v, dtype=np.float64).tolist()


@dataclass(frozen=True)
class ProbeCorrectionParams:
    """Which correction, and the online map's and the consistency check's tuning."""

    UNITS: ClassVar[dict[str, Any]] = {
        "check_s": "s",
        "prior_linear": "1",
        "prior_quadratic": "1",
        "prior_offset_N": "N",
        "tracking_per_sqrt_s": "1/s0.5",
        "reference_sigma_N": "N",
        "tip_S": "m",
        "handle_S": "m",
        "mismatch_time_constant_s": "s",
        "mismatch_threshold_N": "N",
        "across_from_wrist_s": "s",
        "across_within_N": "N",
    }

    kind: CorrectionKind = "none"
    check_s: float = 0.0  # [s] the probe check after the rebias (0: none)
    network: Vec = field(default_factory=lambda: frozen(np.zeros(NETWORK_SIZE)))
    # the online map's Kalman filter: prior σ of Θ's entries around the identity, their random walk,
    # and the reference's σ (the wrist's noise, about 0.3 N, plus the housing's play, up to 0.8 N)
    prior_linear: float = 0.5
    prior_quadratic: float = 0.2
    prior_offset_N: float = 1.0
    tracking_per_sqrt_s: float = 0.002
    reference_sigma_N: float = 0.5
    # the consistency check: where the contact and the hand act, in the wrist sensor's frame
    # (the probe tip 200 mm and the handle 90 mm below S, along -z_S: plant_models.tool)
    tip_S: Vec3 = field(default_factory=lambda: TIP_S.copy())
    handle_S: Vec3 = field(default_factory=lambda: HANDLE_S.copy())
    mismatch_time_constant_s: float = 0.5
    mismatch_threshold_N: float = 2.0  # the play a map without memory leaves, and the grip
    # [s] the probe force across the axis takes its part slower than this from the wrist: the
    # mismatch low-passed again over it is added (0: never; the estimator's docstring)
    across_from_wrist_s: float = 0.0
    # [N] ... and follows the mismatch only while it is within this: the play leaves the probe up to
    # about twice its width off; a larger disagreement is a hand's torque on the handle (which the
    # wrist cannot tell from a contact across the axis) or a fault, and the part holds meanwhile
    across_within_N: float = 1.2

    def __post_init__(self) -> None:
        if self.kind not in CORRECTION_KINDS:
            raise ConfigError(
                f"kind: expected one of {', '.join(CORRECTION_KINDS)}, got {self.kind!r}"
            )
        for name in ("check_s", "tracking_per_sqrt_s", "across_from_wrist_s"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), name, low=0.0))
        for name in (
            "prior_linear",
            "prior_quadratic",
            "prior_offset_N",
            "reference_sigma_N",
            "mismatch_time_constant_s",
            "mismatch_threshold_N",
            "across_within_N",
        ):
            object.__setattr__(
                self, name, as_scalar(getattr(self, name), name, low=0.0, low_open=True)
            )
        object.__setattr__(self, "network", as_vector(self.network, NETWORK_SIZE, "network"))
        for name in ("tip_S", "handle_S"):
            object.__setattr__(self, name, as_vector(getattr(self, name), 3, name))
        d = self.tip_S - self.handle_S
        if float(d @ d) < 1e-6:
            raise ConfigError(
                f"tip_S and handle_S: expected points at least 1 mm apart, got "
                f"{self.tip_S.tolist()} and {self.handle_S.tolist()}"
            )
        if self.kind == "network":
            scales = np.concatenate([self.network[3:6], self.network[9:12]])
            if not np.all(scales > 0.0):
                raise ConfigError(
                    "network: expected trained weights with positive input and output scales "
                    f"(elements 4-6 and 10-12), got {scales.tolist()}: train them with "
                    "'hoh-cosim probe-correction'"
                )


class OnlineProbeMap:
    """The online map f̂ = Θᵀ φ(m): `correct(m)`, and `update(t, m, f_ref)` while the wrist sensor
    is the reference. Θ starts at the identity (f̂ = m) with the prior's uncertainty."""

    def __init__(self, params: ProbeCorrectionParams) -> None:
        self.params = params
        p = params
        # output i: its own stiffening term m_i|m_i| has the prior σ, the other axes' a tenth
        self._P0 = np.array(
            [
                np.diag(
                    [p.prior_linear**2] * 3
                    + [(p.prior_quadratic * (1.0 if j == i else 0.1)) ** 2 for j in range(3)]
                    + [p.prior_offset_N**2]
                )
                for i in range(3)
            ]
        )
        self._q = p.tracking_per_sqrt_s**2
        self._r = p.reference_sigma_N**2
        self._eye = np.eye(FEATURES)
        self.reset()

    def reset(self) -> None:
        self.theta = np.vstack([np.eye(3), np.zeros((4, 3))])
        self.P = self._P0.copy()
        self.updates = 0
        self._t_last: float | None = None

    def correct(self, m: Vec3) -> Vec3:
        return self.theta.T.dot(features(m))

    def update(self, t: float, m: Vec3, f_ref: Vec3) -> Vec3:
        """One reference sample at time t; returns the innovation (f_ref minus the prediction)."""
        if self._t_last is not None and self._q > 0.0:
            self.P = self.P + self._eye * (self._q * max(0.0, t - self._t_last))
        self._t_last = t
        self.theta, self.P, e = map_update(self.theta, self.P, features(m), f_ref, self._r)
        self.updates += 1
        return e


class ProbeCorrection:
    """The correction the estimator applies to each rebiased probe packet (`params.kind`)."""

    def __init__(self, params: ProbeCorrectionParams) -> None:
        self.params = params
        self.online = OnlineProbeMap(params) if params.kind == "online" else None

    def reset(self) -> None:
        if self.online is not None:
            self.online.reset()

    def correct(self, m_P: Vec3) -> Vec3:
        kind = self.params.kind
        if kind == "online":
            assert self.online is not None
            return self.online.correct(m_P)
        if kind == "network":
            return network_forward(self.params.network, m_P)
        return np.array(m_P, dtype=np.float64)

    def reference(self, t: float, m_P: Vec3, f_ref_P: Vec3) -> None:
        """A moment when the wrist sensor is the reference: the online map learns from it."""
        if self.online is not None:
            self.online.update(t, m_P, f_ref_P)


class ContactConsistency:
    """The low-passed disagreement across the probe's axis between the wrist's contact force and the
    corrected probe force (module docstring), and the flag when it passes the threshold."""

    def __init__(self, params: ProbeCorrectionParams, p_SR_S: Vec3) -> None:
        self.params = params
        self._p_RH = np.asarray(params.handle_S) - p_SR_S
        self._p_RT = np.asarray(params.tip_S) - p_SR_S
        self._axis = self._p_RT - self._p_RH
        self._axis_sq = float(self._axis @ self._axis)
        self._p_RH_floats = self._p_RH.tolist()
        self._axis_floats = self._axis.tolist()
        self.reset()

    def reset(self) -> None:
        self.mismatch_S = np.zeros(3)
        self._t_last: float | None = None
        self._norm_of: Vec | None = None  # the mismatch_S that _norm is the norm of

    @property
    def mismatch(self) -> float:
        """|mismatch_S| [N], computed once per `mismatch_S` (which a step replaces, never changes)."""
        if self._norm_of is not self.mismatch_S:
            self._norm = math.sqrt(float(self.mismatch_S.dot(self.mismatch_S)))
            self._norm_of = self.mismatch_S
        return self._norm

    @property
    def drifted(self) -> bool:
        return self.mismatch > self.params.mismatch_threshold_N

    def step(self, t: float, F_S: Vec3, tau_R_S: Vec3, F_probe_S: Vec3) -> float:
        """Fold in the filtered wrist wrench and probe force at time t; returns the mismatch [N].

        F_probe,⊥ = F_probe - d (F_probe·d) / |d|² ;  e = F_contact,⊥ - F_probe,⊥ ;
        mismatch_S ← mismatch_S + a (e - mismatch_S),  a = Δt / (T + Δt)
        """
        d0, d1, d2 = d = self._axis_floats
        k = float(self._axis.dot(F_probe_S)) / self._axis_sq
        p0, p1, p2 = _floats(F_probe_S)
        c0, c1, c2 = _contact_across_axis(F_S, tau_R_S, self._p_RH_floats, d, self._axis_sq)
        e0, e1, e2 = c0 - (p0 - d0 * k), c1 - (p1 - d1 * k), c2 - (p2 - d2 * k)
        dt = 0.0 if self._t_last is None else t - self._t_last
        self._t_last = t
        a = dt / (self.params.mismatch_time_constant_s + dt) if dt > 0.0 else 0.0
        m0, m1, m2 = self.mismatch_S.tolist()
        self.mismatch_S = np.array([m0 + a * (e0 - m0), m1 + a * (e1 - m1), m2 + a * (e2 - m2)])
        return self.mismatch
