"""Constant-acceleration Kalman filters that smooth and upsample force readings (seed 000, section 3.E).

The model is the seed's eq. 9: per axis the state is the force, its rate and its acceleration, and the
acceleration changes by white noise between ticks. The seed's text is inconsistent about the
measurement (it names a 9-value input m, H = I₆ₓ₆ and a 6-value state); we measure the force only
(H = [I₃ 0 0]) and estimate its rate and acceleration, which is what eq. 9 and the seed's
"infer inter-packet force readings" (Fig. 11) need.

The filter predicts on every tick and corrects only when a new sensor packet arrived (`z is None`
means "no packet this tick"): that is how a 200 Hz or 50 Hz sensor feeds a 1 kHz loop.

Implementation. With per-axis process and measurement noise (the seed trusts z more) and a diagonal
initial covariance, the 9-state filter of eq. 9 never couples the axes: it is three independent
3-state filters. We run them as one batch, x of shape (n_axes, 3) and P of shape (n_axes, 3, 3), with
the discrete white-noise process noise of filterpy's `Q_discrete_white_noise` and the Joseph-form
update. That is the same filter as filterpy's `KalmanFilter` on the 9-state matrices (a test checks it
to 1e-10) at a fraction of the cost: on this project's 2-core machine filterpy's `update` on the
9-state matrices takes 28 µs and `predict` 9 µs, and three filters must fit, with the rest of the
estimator and the controller, in 100 µs at p99. `KalmanBank` goes one step further and runs several
such filters as one batch, corrects only the axes that have a reading, and multiplies with
`ndarray.dot`, which calls the same BLAS routine as `@` for a fraction of its overhead on 3x3 arrays.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from hoh_cosim.control.vectors import Vec, Vec3, as_positive_vector, frozen
from hoh_cosim.errors import ConfigError

__all__ = [
    "H_FORCE",
    "ForceKalman",
    "KalmanBank",
    "KalmanParams",
    "SteadyStateForceKalman",
    "axis_transition",
    "predict",
    "process_noise",
    "steady_state_gain",
    "to_seed_covariance",
    "to_seed_state",
    "transition_matrix",
    "update",
]

H_FORCE = frozen(np.hstack([np.eye(3), np.zeros((3, 6))]))
"""Measurement matrix of the 9-state eq. 9 model: the three forces, not their rates or accelerations."""


@dataclass(frozen=True)
class KalmanParams:
    """Tuning of one three-axis filter. Units shown for a force; for a torque read N·m for N.

    q: [N²/s⁵] per axis, how fast the variance of the force's acceleration grows: each tick of length
       dt the acceleration changes by white noise of variance q·dt (filterpy's discrete white-noise
       model), so the tuning does not depend on the tick rate. Larger q follows faster, smooths less.
    r: [N²] per axis, the variance of the sensor's noise. Larger r trusts the sensor less.
    p0: initial variance of (force [N²], rate [N²/s²], acceleration [N²/s⁴]) on every axis.
    """

    UNITS: ClassVar[dict[str, Any]] = {"q": "N2/s5", "r": "N2", "p0": ("N2", "N2/s2", "N2/s4")}

    q: Vec3
    r: Vec3
    p0: Vec3 = field(default_factory=lambda: frozen([100.0, 1.0e4, 1.0e6]))

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", as_positive_vector(self.q, 3, "q"))
        object.__setattr__(self, "r", as_positive_vector(self.r, 3, "r"))
        object.__setattr__(self, "p0", as_positive_vector(self.p0, 3, "p0"))


def axis_transition(dt: float) -> Vec:
    """Per-axis transition of (force, rate, acceleration) over dt: the 3x3 pattern inside eq. 9."""
    return np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])


def transition_matrix(dt: float) -> Vec:
    """The seed's eq. 9: the 9x9 transition of [f_x f_y f_z ḟ_x ḟ_y ḟ_z f̈_x f̈_y f̈_z]."""
    return np.kron(axis_transition(dt), np.eye(3))


def _unit_white_noise(dt: float) -> Vec:
    """The discrete white-noise process noise of a constant-acceleration axis for unit variance:
    filterpy's `Q_discrete_white_noise(dim=3, dt=dt, var=1.0)`, the same numbers (a test checks it
    against filterpy). Written out here because importing filterpy imports scipy.stats, most of a
    second of every run's start-up, for this one 3x3 formula."""
    return np.array(
        [
            [0.25 * dt**4, 0.5 * dt**3, 0.5 * dt**2],
            [0.5 * dt**3, dt**2, dt],
            [0.5 * dt**2, dt, 1.0],
        ]
    )


def process_noise(dt: float, q: Vec) -> Vec:
    """(n_axes, 3, 3) process noise: filterpy's `Q_discrete_white_noise(3, dt, var=q·dt)` per axis."""
    unit = _unit_white_noise(dt)
    return (
        unit[np.newaxis, :, :] * (np.asarray(q, dtype=np.float64) * dt)[:, np.newaxis, np.newaxis]
    )


def predict(x: Vec, P: Vec, F: Vec, Q: Vec, FF: Vec | None = None) -> tuple[Vec, Vec]:
    """x⁻ = F x ;  P⁻ = F P Fᵀ + Q   (per axis; x is (n, 3), P and Q are (n, 3, 3)).

    `FF = kron(F, F)`, if given, computes F P Fᵀ as one product on the flattened covariances
    (vec(F P Fᵀ) = (F ⊗ F) vec(P)), which is what the hot path uses.
    """
    if FF is None:
        return x @ F.T, F @ P @ F.T + Q
    n = P.shape[0]
    return x @ F.T, (P.reshape(n, 9) @ FF.T).reshape(n, 3, 3) + Q


def update(x: Vec, P: Vec, z: Vec, r: Vec, measured: Vec | None = None) -> tuple[Vec, Vec]:
    """Correct with one force reading per axis, in Joseph form.

    S = P₀₀ + r ;  K = P h / S ;  x⁺ = x + K (z - x₀) ;  P⁺ = (I - K hᵀ) P (I - K hᵀ)ᵀ + K r Kᵀ
    with h = (1, 0, 0) per axis. Expanded with P h = P₀ (column 0) the Joseph form is
    P⁺ = P - K P₀ᵀ - P₀ Kᵀ + S K Kᵀ: exact for any gain, symmetric by construction, and a few
    small array operations instead of two 3x3 products per axis.

    `measured` (bool per axis) leaves the axes without a reading untouched (K = 0 there).
    """
    P0 = P[:, :, 0]
    S = P0[:, 0] + r
    K = P0 / S[:, np.newaxis]
    if measured is not None:
        K = K * measured[:, np.newaxis]
    x = x + K * (z - x[:, 0])[:, np.newaxis]
    KP0 = K[:, :, np.newaxis] * P0[:, np.newaxis, :]
    SK = S[:, np.newaxis] * K
    P = P - KP0 - KP0.transpose(0, 2, 1) + SK[:, :, np.newaxis] * K[:, np.newaxis, :]
    return x, P


def to_seed_state(x: Vec) -> Vec:
    """The (3, 3) per-axis state as eq. 9's 9-vector [f_x f_y f_z ḟ_x ḟ_y ḟ_z f̈_x f̈_y f̈_z]."""
    return x.T.reshape(9).copy()


def to_seed_covariance(P: Vec) -> Vec:
    """The (3, 3, 3) per-axis covariance as the 9x9 covariance of eq. 9's state ordering."""
    out = np.zeros((9, 9))
    for axis in range(3):
        idx = [axis, axis + 3, axis + 6]
        out[np.ix_(idx, idx)] = P[axis]
    return out


class KalmanBank:
    """Several three-axis filters (seed eq. 9), each with its own Q and R, stepped as one batch.

    The estimator runs its three filters (hand force, hand torque, probe force) as one bank: one
    prediction and at most one correction per tick instead of three of each.
    """

    def __init__(self, channels: Sequence[KalmanParams]) -> None:
        self.channels = tuple(channels)
        if not self.channels:
            raise ConfigError("a Kalman bank needs at least one channel")
        self._q = np.concatenate([c.q for c in self.channels])
        self._r = np.concatenate([c.r for c in self.channels])
        self._P0 = np.array([np.diag(c.p0) for c in self.channels for _ in range(3)])
        self._blocks: dict[tuple[bool, ...], _Rows | Vec] = {}
        self._dt = math.nan
        self.reset()

    def reset(self) -> None:
        self.x = np.zeros((3 * len(self.channels), 3))  # per axis: force, rate, acceleration
        self._P = self._P0.reshape(-1, 9).copy()  # per axis, the 3x3 covariance row by row
        self._owed = 0  # covariance predictions not applied yet

    @property
    def P(self) -> Vec:
        """The covariance, (3·n, 3, 3), with every prediction so far applied."""
        self._catch_up()
        return self._P.reshape(-1, 3, 3)

    @P.setter
    def P(self, value: Vec) -> None:
        self._P = np.array(value, dtype=np.float64).reshape(-1, 9)  # a copy: corrected in place
        self._owed = 0

    def _model(self, dt: float) -> None:
        self._F = axis_transition(dt)
        self._Ft = self._F.T.copy()
        self._Q = process_noise(dt, self._q)
        self._powers: dict[int, tuple[Vec, Vec, Vec]] = {}
        self._dt = dt

    def _power(self, k: int) -> tuple[Vec, Vec, Vec]:
        """(Fᵏ, kron(Fᵏ, Fᵏ), Qₖ = Σᵢ₌₀ᵏ⁻¹ Fⁱ Q Fⁱᵀ): k predictions of the covariance at once, Qₖ
        flat like the covariance, (3·n, 9)."""
        cached = self._powers.get(k)
        if cached is None:
            if k == 1:
                Fk, Qk = self._F, self._Q
            else:
                Fp, _, Qp = self._power(k - 1)
                Fk, Qk = self._F @ Fp, self._F @ Qp.reshape(-1, 3, 3) @ self._F.T + self._Q
            cached = self._powers[k] = (Fk, np.kron(Fk, Fk), Qk.reshape(-1, 9))
        return cached

    def _catch_up(self) -> None:
        """Apply the owed predictions: P⁻ = Fᵏ P Fᵏᵀ + Qₖ, the same as k single predictions
        (`predict` with FF = kron(Fᵏ, Fᵏ), the state left out: it is predicted every tick)."""
        if self._owed:
            _, FFk, Qk = self._power(self._owed)
            P = self._P.dot(FFk.T)
            P += Qk
            self._P = P
            self._owed = 0

    def step_bank(self, dt: float, measurements: Sequence[Vec3 | None]) -> Vec:
        """Predict all channels, correct those with a reading; the forces of every axis, (3·n,).

        The state is predicted every tick; its covariance is needed only to correct, so its
        predictions are owed and applied together when a reading arrives. The forces returned are a
        view of the state, which no later step changes: read them, never write to them.
        """
        if dt != self._dt:
            self._model(dt)
        # x⁻ = F x per axis; the rows of x are the axes, so x⁻ = x Fᵀ
        self.x = x = self.x.dot(self._Ft)
        self._owed += 1
        for z in measurements:
            if z is not None:
                self._correct(x, measurements)
                break
        return x[:, 0]

    _ZERO3 = frozen(np.zeros(3))

    def _correct(self, x: Vec, measurements: Sequence[Vec3 | None]) -> None:
        """`update` of the axes with a reading, written into this tick's new state x and the
        caught-up covariance (both new, C-ordered arrays that nothing else holds yet)."""
        self._catch_up()
        pattern = tuple([z is not None for z in measurements])
        block = self._blocks.get(pattern)
        if block is None:
            block = self._blocks[pattern] = self._block(pattern)
        if isinstance(block, _Rows):
            readings = [zi for zi in measurements if zi is not None]
            z = readings[0] if len(readings) == 1 else np.concatenate(readings)
            rows = block.rows
            _update_in_place(x[rows], self._P[rows], z, block)
        else:  # channels with a reading between channels without: mask the gain
            z = np.concatenate([self._ZERO3 if zi is None else zi for zi in measurements])
            x[...], P = update(x, self._P.reshape(-1, 3, 3), z, self._r, block)
            self._P = P.reshape(-1, 9)
        # Symmetric in exact arithmetic, not in floating point: each correction and prediction
        # rounds P and Pᵀ apart, and the difference walks on (1.5e-4 N², 4e-4 of P, after 3 h of
        # 1 kHz ticks). Averaged with its transpose at every correction, P is symmetric to the bit
        # after each one, however long the session (the diagonal unchanged: 0.5 (a + a) = a).
        P = self._P
        P += P[:, _TRANSPOSED]
        P *= 0.5

    def _block(self, pattern: tuple[bool, ...]) -> _Rows | Vec:
        """`_Rows` when the channels with a reading are one run of channels, else a mask with 1 on
        the axes of the channels with a reading."""
        on = [i for i, measured in enumerate(pattern) if measured]
        if on == list(range(on[0], on[-1] + 1)):
            rows = slice(3 * on[0], 3 * on[-1] + 3)
            return _Rows(rows, self._r[rows])
        return frozen(np.repeat(np.array(pattern, dtype=float), 3))


_TRANSPOSED = [0, 3, 6, 1, 4, 7, 2, 5, 8]  # a 3x3 matrix row by row -> its transpose row by row


class _Rows:
    """A run of axes that `_update_in_place` corrects: the rows, their r, and where every operand
    of `update` sits in the flattened x (n, 3) and P (n, 3, 3) of those axes (a is the axis, i the
    row and j the column of its 3x3 covariance)."""

    def __init__(self, rows: slice, r: Vec) -> None:
        self.rows = rows
        n = r.size
        a, i, j = np.ogrid[:n, :3, :3]
        self.axis = np.repeat(np.arange(n), 3)  # (a, i) -> a
        self.r = frozen(r[self.axis])  # (a, i) -> r of axis a
        self.x0 = 3 * np.arange(n)  # a -> x[a, 0] in x
        self.a0 = 3 * self.axis  # (a, i) -> P₀[a, 0] in P₀
        self.col0 = (9 * a[:, :, 0] + 3 * i[:, :, 0]).ravel()  # (a, i) -> P[a, i, 0]
        self.ai = np.broadcast_to(3 * a + i, (n, 3, 3)).ravel()  # (a, i, j) -> (a, i)
        self.aj = np.broadcast_to(3 * a + j, (n, 3, 3)).ravel()  # (a, i, j) -> (a, j)
        self.ji = np.broadcast_to(9 * a + 3 * j + i, (n, 3, 3)).ravel()  # (a, i, j) -> (a, j, i)


def _update_in_place(x: Vec, P: Vec, z: Vec, at: _Rows) -> None:
    """`update` without a mask, written into x (n, 3) and P (n, 9: each 3x3 row by row), both
    C-ordered: the same operations on the same numbers, P⁺ = ((P - K P₀ᵀ) - P₀ Kᵀ) + (S K) Kᵀ,
    with every operand gathered into one flat shape first (numpy's broadcasting costs more than
    the arithmetic on arrays this small)."""
    xf, Pf = x.reshape(-1), P.reshape(-1)  # views: written through
    P0 = Pf[at.col0]  # P₀ = P h, column 0
    S = P0[at.a0] + at.r  # S = P₀₀ + r, for every (a, i)
    K = P0 / S
    xf += K * (z - xf[at.x0])[at.axis]  # x⁺ = x + K (z - x₀)
    KP0 = K[at.ai] * P0[at.aj]  # K P₀ᵀ
    SKK = (S * K)[at.ai] * K[at.aj]  # (S K) Kᵀ
    Pf -= KP0
    Pf -= KP0[at.ji]
    Pf += SKK


class ForceKalman(KalmanBank):
    """One three-axis constant-acceleration Kalman filter (seed eq. 9): predict every tick, correct
    when a packet arrived."""

    def __init__(self, params: KalmanParams) -> None:
        self.params = params
        super().__init__([params])

    def step(self, dt: float, z: Vec3 | None) -> Vec3:
        return self.step_bank(dt, (z,)).copy()


def steady_state_gain(params: KalmanParams, dt: float, ticks_per_update: int) -> tuple[Vec, Vec]:
    """Constant gain of the filter when a packet arrives every `ticks_per_update` ticks of `dt`.

    Over one packet period the 9-state model of eq. 9 moves by A = Fᴺ with process noise
    Q_N = Σₖ Fᵏ Q Fᵏᵀ (k < N). python-control's `dlqe` solves the Riccati equation of that system for
    the steady prior covariance P; the correction gain is K = P Hᵀ (H P Hᵀ + R)⁻¹.
    Returns K (9x3) and P (9x9), in eq. 9's state ordering.
    """
    import control  # python-control: imported here, it is slow to import and needed only here

    if ticks_per_update < 1:
        raise ConfigError(f"ticks_per_update must be >= 1, got {ticks_per_update}")
    F = transition_matrix(dt)
    Q1 = process_noise(dt, params.q)
    Q = to_seed_covariance(Q1)
    A = np.eye(9)
    Q_N = np.zeros((9, 9))
    for _ in range(ticks_per_update):
        Q_N = F @ Q_N @ F.T + Q
        A = F @ A
    R = np.diag(params.r)
    _, P, _ = control.dlqe(A, np.eye(9), H_FORCE, Q_N, R, method="scipy")
    P = np.asarray(P)
    K = P @ H_FORCE.T @ np.linalg.inv(H_FORCE @ P @ H_FORCE.T + R)
    return K, P


class SteadyStateForceKalman:
    """The same filter with the constant gain of `steady_state_gain`: no covariance to propagate.

    Exact only while packets arrive every `ticks_per_update` ticks of the design `dt`; a different dt
    is refused. It converges to `ForceKalman`'s output once that filter's covariance has settled.
    """

    def __init__(self, params: KalmanParams, dt: float, ticks_per_update: int) -> None:
        self.params = params
        self.dt = float(dt)
        self.ticks_per_update = int(ticks_per_update)
        self.K, self.P_prior = steady_state_gain(params, self.dt, self.ticks_per_update)
        self._F = transition_matrix(self.dt)
        self.reset()

    def reset(self) -> None:
        self.x = np.zeros(9)  # eq. 9 ordering

    def step(self, dt: float, z: Vec3 | None) -> Vec3:
        if not math.isclose(dt, self.dt, rel_tol=1e-9):
            raise ConfigError(f"dt: the steady-state gain was designed for {self.dt} s, got {dt} s")
        self.x = self._F @ self.x
        if z is not None:
            self.x = self.x + self.K @ (z - self.x[:3])
        return self.x[:3].copy()
