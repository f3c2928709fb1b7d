"""Compiled kernels of the control core's hot path (numba), and the switch to the pure reference.

The estimator's tick on a 1 kHz loop is a few hundred floating-point operations spread over some
20 to 75 small numpy calls (seed 000, Fig. 5: prediction of three constant-acceleration Kalman
filters, eq. 9, a Joseph-form correction when a packet arrived, the consistency check across the
probe's axis and the turn of four vectors into the base frame). Each numpy call costs 0.2-0.3 µs of
dispatch whatever its size, so the tick is dispatch, not arithmetic. One compiled call per tick does
the whole of that arithmetic over the block's own state arrays. The controller's laws past the seed
(issue 22: the variable law with its oscillation watch, the release detector's norms, the
passivity observer and controller), and eq. 10 itself on the force and the torque at once, are the
same kind of arithmetic on 3-vectors, one compiled call each per controller tick; the filter without a gain peak (`lead_lowpass`) is a bank like the
baselines'.

Two implementations, one behaviour:
- the pure one (`hoh_cosim.control.kalman.KalmanBank`, `probe_correction.ContactConsistency`, the
  baseline filters of `baselines.py`, `filters.LeadLowpassFilter`, the estimator's numpy code,
  `variable_admittance.VariableAdmittance`, `release.ReleaseDetector`,
  `passivity.PassivityController`) stays the reference: readable, checked against filterpy, scipy
  and the 1€ filter's reference implementation;
- the compiled one (`KernelKalmanBank`, `KernelConsistency`, `KernelButterworthBank`,
  `KernelOneEuroBank`, `KernelLeadLowpassBank`, `KernelVariableAdmittance`,
  `KernelReleaseDetector`, `KernelPassivityController` below) is the default everywhere the
  estimator and the controller run: in-process, inside the FMUs (they run in the host's Python), in
  the hardware runner and in replay. It computes the same
  formulas, the Kalman bank's in another order (no BLAS, which fuses multiply-adds, and one
  covariance prediction per tick instead of owed ones), so it agrees with the pure path to
  rounding: within 1e-12 relative, tested on recorded inputs, not to the bit.

`HOH_COSIM_KERNELS=pure` in the environment (or `use_kernels(False)`) makes blocks built from then
on take the pure path, e.g. to check a result against the reference.

The kernels are compiled once per machine and cached (`cache=True`: next to this file, or in
numba's user cache when the package directory is read-only, or in `NUMBA_CACHE_DIR`; inside an
unpacked FMU by their source's content, `hoh_cosim.control.jit`); a fresh process loads them from
the cache. `warm_up()` loads (or compiles) them now, so that a real-time loop
never waits for it.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from hoh_cosim.control.admittance import AdmittanceGains, apply_law
from hoh_cosim.control.baselines import ButterworthFilter, OneEuroFilter
from hoh_cosim.control.filters import LeadLowpassFilter
from hoh_cosim.control.jit import HAVE_NUMBA, njit, types
from hoh_cosim.control.kalman import KalmanParams, axis_transition, process_noise
from hoh_cosim.control.passivity import PassivityController, PassivityParams
from hoh_cosim.control.release import ReleaseDetector, ReleaseParams
from hoh_cosim.control.variable_admittance import (
    _SWING_WINDOW_S,
    VariableAdmittance,
    VariableAdmittanceParams,
)
from hoh_cosim.control.vectors import Vec, Vec3
from hoh_cosim.errors import ConfigError

__all__ = [
    "KERNEL_MODES",
    "KernelButterworthBank",
    "KernelConsistency",
    "KernelKalmanBank",
    "KernelLeadLowpassBank",
    "KernelOneEuroBank",
    "KernelPassivityController",
    "KernelReleaseDetector",
    "KernelVariableAdmittance",
    "compiled_bank",
    "deadband_law6",
    "estimator_tick",
    "kernels_enabled",
    "passivity_controller",
    "release_detector",
    "use_kernels",
    "variable_law",
    "warm_up",
    "warm_up_laws",
]

KERNEL_MODES: tuple[str, ...] = ("compiled", "pure")
_ENV = "HOH_COSIM_KERNELS"
_enabled: bool | None = None


def kernels_enabled() -> bool:
    """Whether blocks built now take the compiled path (the default where numba is installed) or
    the pure one (always where it is not: `hoh_cosim.control.jit`)."""
    global _enabled
    if _enabled is None:
        mode = os.environ.get(_ENV, "compiled")
        if mode not in KERNEL_MODES:
            raise ConfigError(f"{_ENV}: expected one of {', '.join(KERNEL_MODES)}, got {mode!r}")
        _enabled = mode == "compiled" and HAVE_NUMBA
    return _enabled


@contextlib.contextmanager
def use_kernels(enabled: bool) -> Iterator[None]:
    """Blocks built inside the `with` take the compiled path if `enabled`, else the pure one."""
    global _enabled
    before = kernels_enabled()
    _enabled = bool(enabled) and HAVE_NUMBA
    try:
        yield
    finally:
        _enabled = before


# --- the Kalman bank (seed 000, eq. 9, section 3.E) ---------------------------------------------
#
# A compiled call costs about 0.1 µs per argument to dispatch, more than the arithmetic of a tick,
# so a bank keeps all its state in one array and all its constants in another:
#   state:     x (n, 3) | P (n, 3, 3) | z (n) | in_S (IN_S_ROWS, 3) | consistency (6)
#   constants: n | F (3, 3) | r (n) | R_SP (3, 3) | consistency (8) | Q (n, 3, 3)
# (n axes; the estimator's in_S rows and the consistency check are used by `estimator_tick` only).

IN_S_ROWS = 7
"""The estimator's rows in S that `estimator_tick` turns into B: F_hand, τ_hand, F_probe (filtered,
the tick's), F_meas (the held wrist packet), F_probe_meas (R_SP f_P, the held probe packet), p_RT
(the tip from the torque's point R) and the probe's axis (the last two constant)."""


def _state_layout(n: int) -> dict[str, slice]:
    rows = 3 * IN_S_ROWS
    return {
        "x": slice(0, 3 * n),
        "P": slice(3 * n, 12 * n),
        "z": slice(12 * n, 13 * n),
        "in_S": slice(13 * n, 13 * n + rows),
        "consistency": slice(13 * n + rows, 13 * n + rows + 6),
    }


@njit(cache=True, nogil=True, inline="always")
def _predict_correct(S, C, lo, hi):  # pragma: no cover - compiled
    """Predict every axis one tick, correct axes lo..hi-1 with their z, symmetrise P.

    x⁻ = F x ;  P⁻ = F P Fᵀ + Q ;  S = P₀₀ + r ;  K = P₀ / S ;  x⁺ = x + K (z - x₀) ;
    P⁺ = P - K P₀ᵀ - P₀ Kᵀ + S K Kᵀ (Joseph form, expanded with P h = P₀) ;  P ← (P + Pᵀ) / 2
    """
    n = int(C[0])
    F = C[1:10]
    r = C[10 : 10 + n]
    Q = C[27 + n :]
    X, Pa, Z = 0, 3 * n, 12 * n
    FP = np.empty(9)
    for a in range(n):
        xa = X + 3 * a
        x0, x1, x2 = S[xa], S[xa + 1], S[xa + 2]
        for i in range(3):
            S[xa + i] = F[3 * i] * x0 + F[3 * i + 1] * x1 + F[3 * i + 2] * x2
        # FP = F P, then P = (F P) Fᵀ + Q
        pa = Pa + 9 * a
        for i in range(3):
            for j in range(3):
                FP[3 * i + j] = (
                    F[3 * i] * S[pa + j]
                    + F[3 * i + 1] * S[pa + 3 + j]
                    + F[3 * i + 2] * S[pa + 6 + j]
                )
        for i in range(3):
            for j in range(3):
                S[pa + 3 * i + j] = (
                    FP[3 * i] * F[3 * j]
                    + FP[3 * i + 1] * F[3 * j + 1]
                    + FP[3 * i + 2] * F[3 * j + 2]
                ) + Q[9 * a + 3 * i + j]
    if hi <= lo:
        return
    K = np.empty(3)
    P0 = np.empty(3)
    for a in range(lo, hi):
        pa, xa = Pa + 9 * a, X + 3 * a
        P0[0], P0[1], P0[2] = S[pa], S[pa + 3], S[pa + 6]
        s = P0[0] + r[a]
        innovation = S[Z + a] - S[xa]
        for i in range(3):
            K[i] = P0[i] / s
            S[xa + i] += K[i] * innovation
        for i in range(3):
            for j in range(3):
                S[pa + 3 * i + j] = ((S[pa + 3 * i + j] - K[i] * P0[j]) - P0[i] * K[j]) + (
                    s * K[i]
                ) * K[j]
    for a in range(n):
        pa = Pa + 9 * a
        for i in range(3):
            for j in range(i + 1, 3):
                m = (S[pa + 3 * i + j] + S[pa + 3 * j + i]) * 0.5
                S[pa + 3 * i + j] = m
                S[pa + 3 * j + i] = m


@njit(cache=True, nogil=True)
def _bank_step(S, C, lo, hi):  # pragma: no cover - compiled
    _predict_correct(S, C, lo, hi)


class KernelKalmanBank:
    """`KalmanBank`'s filters, compiled: the same channels, reset, `x`, `P` and `step_bank`, and
    the estimator's fused tick (`estimator_tick`) over the same state array."""

    def __init__(self, channels: Sequence[KalmanParams]) -> None:
        self.channels = tuple(channels)
        if not self.channels:
            raise ConfigError("a Kalman bank needs at least one channel")
        self.n = n = 3 * len(self.channels)
        self._q = np.concatenate([c.q for c in self.channels])
        self._P0 = np.array([np.diag(c.p0) for c in self.channels for _ in range(3)])
        self.state = np.zeros(_state_layout(n)["consistency"].stop)
        self._views()
        r = np.concatenate([c.r for c in self.channels])
        # n | F | r | R_SP | consistency | Q
        self.constants = np.zeros(27 + n + 9 * n)
        self.constants[0] = n
        self.constants[10 : 10 + n] = r
        self._dt = math.nan
        self.reset()

    def _views(self) -> None:
        """The parts of `state`, as views written in place."""
        n, layout = self.n, _state_layout(self.n)
        self.x = self.state[layout["x"]].reshape(n, 3)
        self._P = self.state[layout["P"]].reshape(n, 3, 3)
        self.z = self.state[layout["z"]]
        self.in_S = self.state[layout["in_S"]].reshape(IN_S_ROWS, 3)
        self.consistency_state = self.state[layout["consistency"]]

    # A copy (pickle, deepcopy: an FMU's state) would turn the views into arrays of their own:
    # copies are made without them, and they are made anew.
    _VIEWS = ("x", "_P", "z", "in_S", "consistency_state")

    def __getstate__(self) -> dict[str, object]:
        return {k: v for k, v in self.__dict__.items() if k not in self._VIEWS}

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        self._views()

    def reset(self) -> None:
        self.x[...] = 0.0  # per axis: force, rate, acceleration
        self._P[...] = self._P0

    @property
    def P(self) -> Vec:
        """The covariance, (3·n, 3, 3), predicted to the last step."""
        return self._P

    @P.setter
    def P(self, value: Vec) -> None:
        self._P[...] = np.asarray(value, dtype=np.float64).reshape(-1, 3, 3)

    def set_rotation(self, R_SP: Vec) -> None:
        """R_SP, which `estimator_tick` turns the third channel's forces into S with."""
        self.constants[10 + self.n : 19 + self.n] = np.asarray(R_SP, dtype=np.float64).ravel()

    def set_consistency(self, constants: Vec) -> None:
        """The consistency check's constants (`KernelConsistency.constants`)."""
        self.constants[19 + self.n : 27 + self.n] = constants

    def model(self, dt: float) -> None:
        """The transition and process noise of a tick of `dt` (kept until dt changes)."""
        if dt != self._dt:
            self.constants[1:10] = axis_transition(dt).ravel()
            self.constants[27 + self.n :] = process_noise(dt, self._q).ravel()
            self._dt = dt

    def step_bank(self, dt: float, measurements: Sequence[Vec3 | None]) -> Vec:
        """Predict all channels, correct those with a reading (one run of channels); the forces of
        every axis, (3·n,), a new array."""
        self.model(dt)
        on = [i for i, z in enumerate(measurements) if z is not None]
        lo = hi = 0
        if on:
            if on != list(range(on[0], on[-1] + 1)):
                raise ConfigError(
                    "a compiled Kalman bank corrects one run of channels at a time, got "
                    f"readings on channels {on}"
                )
            lo, hi = 3 * on[0], 3 * on[-1] + 3
            for i in on:
                self.z[3 * i : 3 * i + 3] = measurements[i]
        _bank_step(self.state, self.constants, lo, hi)
        return self.x[:, 0].copy()


# --- the consistency check across the probe's axis (probe_correction.ContactConsistency) --------


class KernelConsistency:
    """`ContactConsistency`'s state as an array the fused tick updates (the mismatch in S, the
    time of the last step, whether there was one, |mismatch|); `reset`, `mismatch` and
    `mismatch_S` as there. `attach` makes it use a bank's state array."""

    def __init__(self, params: object, p_SR_S: Vec3) -> None:
        self.params = params
        p_RH = np.asarray(params.handle_S) - p_SR_S  # type: ignore[attr-defined]
        p_RT = np.asarray(params.tip_S) - p_SR_S  # type: ignore[attr-defined]
        axis = p_RT - p_RH
        # d (3), p_RH (3), d·d, the time constant T
        self.constants = np.array(
            [
                *axis.tolist(),
                *p_RH.tolist(),
                float(axis @ axis),
                params.mismatch_time_constant_s,  # type: ignore[attr-defined]
            ]
        )
        self._own = np.zeros(6)
        self._bank: KernelKalmanBank | None = None
        self.reset()

    def attach(self, bank: KernelKalmanBank) -> None:
        """Keep the state in `bank`'s state array, where `estimator_tick` updates it."""
        bank.set_consistency(self.constants)
        bank.consistency_state[...] = self._own
        self._bank = bank

    @property
    def state(self) -> Vec:
        """mismatch_S (3), the time of the last step, 1 once there was one, |mismatch_S|."""
        return self._own if self._bank is None else self._bank.consistency_state

    def reset(self) -> None:
        self.state[...] = 0.0

    @property
    def mismatch_S(self) -> Vec3:
        return self.state[:3].copy()

    @property
    def mismatch(self) -> float:
        return float(self.state[5])

    def step(self, t: float, F_S: Vec3, tau_R_S: Vec3, F_probe_S: Vec3) -> float:
        rows = np.array([F_S, tau_R_S, F_probe_S], dtype=np.float64).ravel()
        _consistency(self.state, self.constants, t, rows)
        return float(self.state[5])


@njit(cache=True, nogil=True, inline="always")
def _consistency_at(state, c, t, rows):  # pragma: no cover - compiled
    """probe_correction.ContactConsistency.step on arrays (rows: F, τ_R, F_probe in S, 9):
    τ' = τ_R - p_RH × F ;  F_contact,⊥ = (τ' × d) / d·d ;  F_probe,⊥ = F_probe - d (F_probe·d) / d·d ;
    e = F_contact,⊥ - F_probe,⊥ ;  m ← m + a (e - m),  a = Δt / (T + Δt)"""
    d0, d1, d2, h0, h1, h2, dd, T = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]
    f0, f1, f2 = rows[0], rows[1], rows[2]
    p0, p1, p2 = rows[6], rows[7], rows[8]
    k = (d0 * p0 + d1 * p1 + d2 * p2) / dd
    t0 = rows[3] - (h1 * f2 - h2 * f1)
    t1 = rows[4] - (h2 * f0 - h0 * f2)
    t2 = rows[5] - (h0 * f1 - h1 * f0)
    c0 = (t1 * d2 - t2 * d1) / dd
    c1 = (t2 * d0 - t0 * d2) / dd
    c2 = (t0 * d1 - t1 * d0) / dd
    e0 = c0 - (p0 - d0 * k)
    e1 = c1 - (p1 - d1 * k)
    e2 = c2 - (p2 - d2 * k)
    dt = t - state[3] if state[4] != 0.0 else 0.0
    state[3] = t
    state[4] = 1.0
    a = dt / (T + dt) if dt > 0.0 else 0.0
    m0 = state[0] + a * (e0 - state[0])
    m1 = state[1] + a * (e1 - state[1])
    m2 = state[2] + a * (e2 - state[2])
    state[0], state[1], state[2] = m0, m1, m2
    state[5] = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)


@njit(cache=True, nogil=True)
def _consistency(state, c, t, rows):  # pragma: no cover - compiled
    _consistency_at(state, c, t, rows)


# --- the estimator's tick once ready (estimator.Estimator.step) ---------------------------------


_IN = types.Array(types.float64, 1, "A", readonly=True)
"""An input vector of any layout, writable or not: one compiled version for every caller, never a
compile in a running loop."""


@njit(
    types.void(types.float64[::1], _IN, _IN, types.float64, types.int64, types.float64[:, ::1]),
    cache=True,
    nogil=True,
)
def _estimator_tick(S, C, R_BS, t, code, in_B):  # pragma: no cover - compiled
    """The bank's tick (`_predict_correct`: axes lo..hi-1 corrected, code = lo + 16 hi + 256 check),
    the filtered forces into in_S (rows F_hand, τ_hand, F_probe = R_SP F_P, in S; the other rows
    (`IN_S_ROWS`) are the caller's), the consistency check if asked, every row turned into B:
    row_B = row_S R_BSᵀ (R_BS row by row, 9 values), and in the last row of `in_B` the contact's
    moment about R, p_RT_B × F_probe_B. `in_B` (IN_S_ROWS + 1, 3) is a new array made by the caller
    (a compiled function's own new array costs twice as much to return)."""
    lo, hi, check = code % 16, (code // 16) % 16, code >= 256
    _predict_correct(S, C, lo, hi)
    n = int(C[0])
    R_SP = C[10 + n : 19 + n]
    at = 13 * n  # in_S
    for i in range(3):
        S[at + i] = S[3 * i]
        S[at + 3 + i] = S[9 + 3 * i]
    f0, f1, f2 = S[18], S[21], S[24]
    for i in range(3):
        S[at + 6 + i] = R_SP[3 * i] * f0 + R_SP[3 * i + 1] * f1 + R_SP[3 * i + 2] * f2
    rows = in_B.shape[0] - 1
    if check:
        at_c = at + 3 * rows
        _consistency_at(S[at_c : at_c + 6], C[19 + n : 27 + n], t, S[at : at + 9])
    for k in range(rows):
        s0, s1, s2 = S[at + 3 * k], S[at + 3 * k + 1], S[at + 3 * k + 2]
        for i in range(3):
            in_B[k, i] = R_BS[3 * i] * s0 + R_BS[3 * i + 1] * s1 + R_BS[3 * i + 2] * s2
    r0, r1, r2 = in_B[5, 0], in_B[5, 1], in_B[5, 2]  # p_RT_B
    f0, f1, f2 = in_B[2, 0], in_B[2, 1], in_B[2, 2]  # F_probe_B
    in_B[rows, 0] = r1 * f2 - r2 * f1
    in_B[rows, 1] = r2 * f0 - r0 * f2
    in_B[rows, 2] = r0 * f1 - r1 * f0


def estimator_tick(
    bank: KernelKalmanBank,
    dt: float,
    ft_z: Vec | None,
    probe_z: Vec3 | None,
    R_BS: Vec,
    t: float,
    check: bool,
) -> Vec:
    """One ready tick of the estimator's arithmetic in one compiled call; the rows of the bank's
    `in_S` in B and then the contact's moment about R (p_RT_B × F_probe_B), a new array of
    `IN_S_ROWS` + 1 rows. `ft_z`: the compensated wrench (6) of a new FT-150
    packet or None; `probe_z`: the corrected force (3) of a new probe packet or None; `check`: step
    the consistency check (attached to the bank). A bank of three channels (9 axes)."""
    if dt != bank._dt:
        bank.model(dt)
    lo, hi = 9, 0  # the axes corrected: lo..hi-1
    if ft_z is not None:
        bank.z[:6] = ft_z
        lo, hi = 0, 6
    if probe_z is not None:
        bank.z[6:9] = probe_z
        lo, hi = min(lo, 6), 9
    code = lo + 16 * hi
    in_B = np.empty((IN_S_ROWS + 1, 3))
    _estimator_tick(bank.state, bank.constants, R_BS, t, code + 256 * check, in_B)
    return in_B


# --- the baseline filters (baselines.ButterworthFilter, baselines.OneEuroFilter) ----------------
#
# The estimator runs three of one kind (hand force, hand torque, probe force); compiled, the three
# are one bank stepped in one call, like the Kalman bank.


@njit(cache=True, nogil=True)
def _butterworth(sections, zi, held, on, out):  # pragma: no cover - compiled
    """One sample of every axis that has had a packet (on[a] = 1) through the second-order sections
    (b0, b1, b2, a1, a2), transposed direct form II as scipy's `sosfilt`, the same operations in the
    same order (the others give 0):
    y = b0 x + s0 ;  s0 ← b1 x - a1 y + s1 ;  s1 ← b2 x - a2 y ;  x ← y   (each section)"""
    for a in range(held.shape[0]):
        if on[a] == 0.0:
            out[a] = 0.0
            continue
        x = held[a]
        for k in range(sections.shape[0]):
            y = sections[k, 0] * x + zi[a, k, 0]
            zi[a, k, 0] = sections[k, 1] * x - sections[k, 3] * y + zi[a, k, 1]
            zi[a, k, 1] = sections[k, 2] * x - sections[k, 4] * y
            x = y
        out[a] = x


class KernelButterworthBank:
    """Three-axis `ButterworthFilter`s, one per channel, compiled as one bank: the same design
    (scipy's, at the first step), the same steady start at each channel's first packet, the same
    numbers."""

    def __init__(self, filters: Sequence[ButterworthFilter]) -> None:
        self.filters = tuple(filters)  # the designs (pure objects: never stepped)
        self.n = 3 * len(self.filters)
        self._dt = math.nan
        self.reset()

    def reset(self) -> None:
        self._held = np.zeros(self.n)
        self._on = np.zeros(self.n)  # 1 on the axes of a channel that has had a packet
        self._zi: Vec | None = None if math.isnan(self._dt) else np.zeros_like(self._zi)

    def step_bank(self, dt: float, measurements: Sequence[Vec | None]) -> Vec:
        if dt != self._dt:
            if not math.isnan(self._dt):
                raise ConfigError(f"dt: the filter was designed for {self._dt} s, got {dt} s")
            first = self.filters[0]
            first._design(dt)
            for f in self.filters[1:]:
                if f.params != first.params:
                    raise ConfigError("a compiled Butterworth bank needs one design")
            self._sections = np.array(first._sections, dtype=np.float64)
            self._unit = np.array(first._zi_unit, dtype=np.float64)
            self._zi = np.zeros((self.n, len(first._sections), 2))
            self._dt = dt
        for c, z in enumerate(measurements):
            if z is not None:
                axes = slice(3 * c, 3 * c + 3)
                self._held[axes] = z
                if self._on[3 * c] == 0.0:  # the steady state for the channel's first packet
                    self._zi[axes] = self._held[axes, np.newaxis, np.newaxis] * self._unit
                    self._on[axes] = 1.0
        out = np.empty(self.n)
        _butterworth(self._sections, self._zi, self._held, self._on, out)
        return out


@njit(cache=True, nogil=True)
def _one_euro(x_hat, dx_hat, since, started, z, on, dt, c, out):  # pragma: no cover - compiled
    """Every channel's `OneEuroFilter` step (3 axes a channel): `since` += dt; on a packet
    (on[channel] = 1) the first initialises x̂ = z, the others, with rate = 1 / since and
    c[channel] = (min_cutoff, β, d_cutoff):
    dx = (z - x̂) rate ;  dx̂ ← dx̂ + α(rate, d_cutoff) (dx - dx̂) ;  fc = min_cutoff + β |dx̂| ;
    x̂ ← x̂ + α(rate, fc) (z - x̂) ;  α(rate, fc) = 1 / (1 + τ rate), τ = 1 / (2π fc);
    then `since` = 0. x̂ into `out`."""
    for ch in range(since.shape[0]):
        since[ch] += dt
        if on[ch] != 0.0:
            if started[ch] == 0.0:
                for i in range(3 * ch, 3 * ch + 3):
                    x_hat[i] = z[i]
                started[ch] = 1.0
            else:
                rate = 1.0 / since[ch]
                tau_d = 1.0 / (2.0 * math.pi * c[ch, 2])
                alpha_d = 1.0 / (1.0 + tau_d * rate)
                for i in range(3 * ch, 3 * ch + 3):
                    dx = (z[i] - x_hat[i]) * rate
                    dx_hat[i] = dx_hat[i] + alpha_d * (dx - dx_hat[i])
                    tau = 1.0 / (2.0 * math.pi * (c[ch, 0] + c[ch, 1] * abs(dx_hat[i])))
                    alpha = 1.0 / (1.0 + tau * rate)
                    x_hat[i] = x_hat[i] + alpha * (z[i] - x_hat[i])
            since[ch] = 0.0
    for i in range(x_hat.shape[0]):
        out[i] = x_hat[i]


class KernelOneEuroBank:
    """Three-axis `OneEuroFilter`s, one per channel with its own tuning, compiled as one bank."""

    def __init__(self, filters: Sequence[OneEuroFilter]) -> None:
        self.filters = tuple(filters)
        self._c = np.array(
            [[f.params.min_cutoff_hz, f.params.beta, f.params.d_cutoff_hz] for f in filters]
        )
        self._z = np.zeros(3 * len(self.filters))
        self._on = np.zeros(len(self.filters))
        self.reset()

    def reset(self) -> None:
        n = len(self.filters)
        self._x_hat, self._dx_hat = np.zeros(3 * n), np.zeros(3 * n)
        self._since, self._started = np.zeros(n), np.zeros(n)

    def step_bank(self, dt: float, measurements: Sequence[Vec | None]) -> Vec:
        on = self._on
        for c, z in enumerate(measurements):
            if z is None:
                on[c] = 0.0
            else:
                on[c] = 1.0
                self._z[3 * c : 3 * c + 3] = z
        out = np.empty(self._x_hat.size)
        _one_euro(
            self._x_hat, self._dx_hat, self._since, self._started, self._z, on, dt, self._c, out
        )
        return out


def compiled_bank(filters: Sequence[object]) -> KernelButterworthBank | KernelOneEuroBank | None:
    """The compiled bank of these three-axis filters if they are all of one compiled kind (and the
    Butterworth filters of one design), else None."""
    if filters and all(
        type(f) is ButterworthFilter and f.size == 3 and f.params == filters[0].params  # type: ignore[attr-defined]
        for f in filters
    ):
        return KernelButterworthBank(filters)  # type: ignore[arg-type]
    if filters and all(type(f) is OneEuroFilter and f.size == 3 for f in filters):
        return KernelOneEuroBank(filters)  # type: ignore[arg-type]
    if filters and all(type(f) is LeadLowpassFilter and f.size == 3 for f in filters):
        return KernelLeadLowpassBank(filters)  # type: ignore[arg-type]
    return None


# --- the passivity observer and controller (passivity.PassivityController) ---------------------
#
# state: E, t_prev, has t_prev, p_prev (3), the energy dissipated, E_max

_P_E, _P_T, _P_HAS_T, _P_P, _P_DISSIPATED, _P_MAX = 0, 1, 2, 3, 6, 7
_PASSIVITY = types.float64(
    types.float64[::1], types.float64, _IN, _IN, _IN, types.boolean, types.float64[::1]
)


@njit(cache=True, nogil=True)
def _passivity(S, t, F, p_B, v_c, control, out):  # pragma: no cover - compiled
    """PassivityController.step: the PO, E ← min(E_max, E + F̂ · (p - p_prev)); then, if
    `control` and Δt > 0, the PC: P = F̂ · v_c ; if E + P Δt < 0 (and F̂ ≠ 0):
    out = v_c + β F̂,  β = -(E + P Δt) / (Δt ‖F̂‖²), and 1 is returned (else 0, out untouched)."""
    dt = 0.0
    if S[_P_HAS_T] != 0.0 and t > S[_P_T]:
        dt = t - S[_P_T]
        work = (
            F[0] * (p_B[0] - S[_P_P])
            + F[1] * (p_B[1] - S[_P_P + 1])
            + F[2] * (p_B[2] - S[_P_P + 2])
        )
        S[_P_E] = min(S[_P_MAX], S[_P_E] + work)
    S[_P_T], S[_P_HAS_T] = t, 1.0
    for i in range(3):
        S[_P_P + i] = p_B[i]
    if not control or dt <= 0.0:
        return 0.0
    deficit = S[_P_E] + (F[0] * v_c[0] + F[1] * v_c[1] + F[2] * v_c[2]) * dt
    FF = F[0] * F[0] + F[1] * F[1] + F[2] * F[2]
    if deficit >= 0.0 or FF == 0.0:
        return 0.0
    beta = -deficit / (dt * FF)
    S[_P_DISSIPATED] += -deficit
    for i in range(3):
        out[i] = v_c[i] + beta * F[i]
    return 1.0


class KernelPassivityController:
    """`PassivityController`, compiled: the same parameters, `energy_J`, `dissipated_J`, `reset`
    and `step` (the PO and the PC in one call), the state in one array."""

    def __init__(self, params: PassivityParams | None = None) -> None:
        warm_up_laws()
        self.state = np.zeros(8)
        self.params = params or PassivityParams()
        self.reset()

    @property
    def params(self) -> PassivityParams:
        return self._params

    @params.setter
    def params(self, params: PassivityParams) -> None:
        self._params = params
        self.state[_P_MAX] = params.tank_max_J

    def reset(self) -> None:
        S = self.state
        S[:_P_MAX] = 0.0
        S[_P_E] = self.params.tank_max_J  # the tank starts full

    energy_J = property(lambda self: float(self.state[_P_E]), doc="E, the tank's content")
    dissipated_J = property(
        lambda self: float(self.state[_P_DISSIPATED]), doc="what the PC dissipated"
    )

    def step(self, t: float, F: Vec3, p_B: Vec3, v_c: Vec3, control: bool) -> tuple[Vec3, bool]:
        out = np.empty(3)
        if _passivity(self.state, t, F, p_B, v_c, control, out) != 0.0:
            return out, True
        return v_c, False


def _load(dispatcher: Any, signature: Any) -> None:
    """Compile `dispatcher` for one signature (or load it from the cache) and let it compile no
    other: every caller's arguments convert to that one, so that no call compiles a new version
    in a running loop. At the first use instead of at import, which would cost every process
    that imports this module the load (0.3-0.5 s a function here)."""
    if not dispatcher.signatures:
        dispatcher.compile(signature)
        dispatcher.disable_compile()


_warm: set[str] = set()
"""What `warm_up` has loaded in this process: "estimator" (the Kalman bank, the consistency check,
the fused tick) and the baseline filters' banks by filter kind."""

_BASELINES = ("one_euro", "butterworth", "lead_lowpass")


def warm_up(filter: str | None = None) -> None:
    """Load (or compile) the control kernels now, with the argument types the blocks use (once
    per process; the blocks call it when they are built): the estimator's, and the baseline bank of
    `filter` if it has one (None: every filter's, as a test session does before its workers start).
    Only the filter in use is loaded: the Butterworth bank's warm-up needs scipy.signal, most of a
    second of every runner's start for a filter the rig may not use."""
    wanted = {"estimator", *(b for b in _BASELINES if filter in (None, b))}
    if filter is None:
        warm_up_laws()
    if wanted <= _warm:
        return
    from hoh_cosim.control.baselines import ButterworthParams, OneEuroParams
    from hoh_cosim.control.probe_correction import ProbeCorrectionParams

    if "estimator" not in _warm:
        bank = KernelKalmanBank([KalmanParams(q=[1.0] * 3, r=[1.0] * 3)] * 3)
        bank.step_bank(1e-3, (np.zeros(3), None, None))
        cons = KernelConsistency(ProbeCorrectionParams(), np.zeros(3))
        cons.step(0.0, np.zeros(3), np.zeros(3), np.zeros(3))
        cons.attach(bank)
        bank.set_rotation(np.eye(3))
        estimator_tick(bank, 1e-3, np.zeros(6), np.zeros(3), np.zeros(9), 0.0, True)
        _warm.add("estimator")
    if "one_euro" in wanted - _warm:
        euro = KernelOneEuroBank([OneEuroFilter(OneEuroParams())] * 3)
        for _ in range(2):
            euro.step_bank(1e-3, (np.zeros(3), None, np.zeros(3)))
        _warm.add("one_euro")
    if "lead_lowpass" in wanted - _warm:
        from hoh_cosim.control.filters import LeadLowpassParams

        bank = KernelLeadLowpassBank([LeadLowpassFilter(LeadLowpassParams(), 0.005)] * 3)
        bank.step_bank(1e-3, (np.zeros(3), None, np.zeros(3)))
        _warm.add("lead_lowpass")
    if "butterworth" in wanted - _warm:
        KernelButterworthBank([ButterworthFilter(ButterworthParams())] * 3).step_bank(
            1e-3, (np.zeros(3), None, None)
        )
        _warm.add("butterworth")


# --- the filter without a gain peak (filters.LeadLowpassFilter) ---------------------------------


@njit(cache=True, nogil=True)
def _lead_lowpass(X, U, Y, started, C, z, on, out):  # pragma: no cover - compiled
    """Every channel's `LeadLowpassFilter` step (3 axes a channel, C[channel] = (b0, b1, a1, c0,
    c1, d1)): on a packet (on[channel] = 1) the first sets x₋ = u₋ = y = z (its steady state),
    then u = b0 x + b1 x₋ - a1 u₋ ;  y = c0 u + c1 u₋ - d1 y₋ ;  x₋ = x ;  u₋ = u.
    y (held between packets) into `out`."""
    for ch in range(started.shape[0]):
        if on[ch] == 0.0:
            continue
        b0, b1, a1, c0, c1, d1 = C[ch, 0], C[ch, 1], C[ch, 2], C[ch, 3], C[ch, 4], C[ch, 5]
        if started[ch] == 0.0:
            for i in range(3 * ch, 3 * ch + 3):
                X[i] = U[i] = Y[i] = z[i]
            started[ch] = 1.0
        for i in range(3 * ch, 3 * ch + 3):
            x = z[i]
            u = b0 * x + b1 * X[i] - a1 * U[i]
            Y[i] = c0 * u + c1 * U[i] - d1 * Y[i]
            X[i], U[i] = x, u
    for i in range(Y.shape[0]):
        out[i] = Y[i]


class KernelLeadLowpassBank:
    """Three-axis `LeadLowpassFilter`s, one per channel with its own packet period, compiled as
    one bank: the same sections, the same steady start at each channel's first packet."""

    def __init__(self, filters: Sequence[LeadLowpassFilter]) -> None:
        self.filters = tuple(filters)
        self._c = np.array(
            [[f._b0, f._b1, f._a1, f._c0, f._c1, f._d1] for f in self.filters], dtype=np.float64
        )
        n = len(self.filters)
        self._z = np.zeros(3 * n)
        self._on = np.zeros(n)
        self.reset()

    def reset(self) -> None:
        n = len(self.filters)
        self._x, self._u, self._y = np.zeros(3 * n), np.zeros(3 * n), np.zeros(3 * n)
        self._started = np.zeros(n)

    def step_bank(self, dt: float, measurements: Sequence[Vec | None]) -> Vec:
        on = self._on
        for c, z in enumerate(measurements):
            if z is None:
                on[c] = 0.0
            else:
                on[c] = 1.0
                self._z[3 * c : 3 * c + 3] = z
        out = np.empty(self._y.size)
        _lead_lowpass(self._x, self._u, self._y, self._started, self._c, self._z, on, out)
        return out


# --- the variable law (variable_admittance.VariableAdmittance) ----------------------------------
#
# state:     t_prev, has t_prev, e_prev, g, h, c, the watch's clock, t of the last halving, has
#            one, margined, σ, has p_prev | p_prev (3) | v_prev (3) | u1 (3) | u (3) | s (3)
# constants: k, ė_ref, g_min, g_max, f_o, T_w, σ_o, watch on, T_q, ρ, h_min, c_o |
#            α, η of the translation (3 + 3) | α, η of the rotation (3 + 3)

_V_T, _V_HAS_T, _V_E, _V_G, _V_H, _V_C, _V_CLOCK, _V_HALVED, _V_HAS_HALVED = range(9)
_V_MARGINED, _V_SIGMA, _V_HAS_P, _V_P, _V_V, _V_U1, _V_U, _V_S = 9, 10, 11, 12, 15, 18, 21, 24
_V_STATE = 27
_V_GAINS = 12  # where the gains start in the constants
_V_CONSTANTS = _V_GAINS + 12
_VAR_WATCH, _VAR_ROTATION = 1, 2  # `_variable_law`'s code


@njit(cache=True, nogil=True, inline="always")
def _scaled_norm_at(F, eta):  # pragma: no cover - compiled
    """release.scaled_norm: ‖F ⊘ η‖ over the axes with η > 0."""
    total = 0.0
    for i in range(3):
        if eta[i] > 0.0:
            total += (F[i] / eta[i]) ** 2
    return math.sqrt(total)


@njit(cache=True, nogil=True, inline="always")
def _eq10_at(F, slope_scale, slope, eta, out, at):  # pragma: no cover - compiled
    """admittance.deadband_linear with the slope (s α): out[at + i] = sgn Fᵢ (s αᵢ) max(|Fᵢ| - ηᵢ, 0)"""
    for i in range(3):
        excess = abs(F[i]) - eta[i]
        if excess < 0.0:
            excess = 0.0
        out[at + i] = (np.sign(F[i]) * (slope_scale * slope[i])) * excess


@njit(cache=True, nogil=True, inline="always")
def _oscillation_watch(S, C, dt, p_B):  # pragma: no cover - compiled
    """VariableAdmittance._watch: the tip's velocity high-passed twice, its power over T_w, the
    swings, and the halvings of h (variable_admittance's module docstring)."""
    if S[_V_HAS_P] != 0.0:
        tau = 1.0 / (2.0 * math.pi * C[4])
        a = tau / (tau + dt)
        power = 0.0
        for i in range(3):
            v = (p_B[i] - S[_V_P + i]) / dt
            # first-order high-pass twice: u ← a (u + x - x_prev)
            u1 = a * (S[_V_U1 + i] + v - S[_V_V + i])
            u = a * (S[_V_U + i] + u1 - S[_V_U1 + i])
            S[_V_V + i], S[_V_U1 + i], S[_V_U + i] = v, u1, u
            power += u * u
        ms = S[_V_SIGMA] ** 2
        ms += min(1.0, dt / C[5]) * (power - ms)
        S[_V_SIGMA] = math.sqrt(ms)
        S[_V_C] *= math.exp(-dt / _SWING_WINDOW_S)
        for i in range(3):
            u = S[_V_U + i]
            if abs(u) > C[6]:
                sign = math.copysign(1.0, u)
                if S[_V_S + i] == -sign:
                    S[_V_C] += 1.0
                S[_V_S + i] = sign
        S[_V_CLOCK] += dt
        if S[_V_SIGMA] > C[6] and S[_V_C] >= C[11]:  # oscillating: halve, count afresh
            S[_V_H] = max(C[10], 0.5 * S[_V_H])
            S[_V_C] = 0.0
            S[_V_HALVED], S[_V_HAS_HALVED], S[_V_MARGINED] = S[_V_CLOCK], 1.0, 0.0
        elif (
            S[_V_MARGINED] == 0.0 and S[_V_HAS_HALVED] != 0.0 and S[_V_CLOCK] - S[_V_HALVED] >= C[8]
        ):  # quiet at h after oscillating at 2h: h/2
            S[_V_H] = max(C[10], 0.5 * S[_V_H])
            S[_V_MARGINED] = 1.0
        elif S[_V_MARGINED] != 0.0:
            S[_V_H] = min(1.0, S[_V_H] * math.exp(C[9] * dt))
    for i in range(3):
        S[_V_P + i] = p_B[i]
    S[_V_HAS_P] = 1.0


_VARIABLE_LAW = types.void(
    types.float64[::1],
    types.float64[::1],
    types.float64,
    _IN,
    _IN,
    _IN,
    types.int64,
    types.float64[::1],
)


@njit(cache=True, nogil=True)
def _variable_law(S, C, t, F, tau, p_B, code, out):  # pragma: no cover - compiled
    """VariableAdmittance.step into out[:3] (code & 1: with the oscillation watch on p_B), and
    with code & 2 the rotation's eq. 10 of tau into out[3:]:
    e = max(0, ‖F ⊘ η‖ - 1) ;  ė = (e - e_prev)/Δt ;  g = clip(1 + k tanh(ė/ė_ref), g_min, g_max) ;
    v = sgn F (h g α) max(|F| - η, 0)"""
    e = max(0.0, _scaled_norm_at(F, C[_V_GAINS + 3 : _V_GAINS + 6]) - 1.0)
    has_dt = S[_V_HAS_T] != 0.0
    dt = t - S[_V_T] if has_dt else 0.0
    e_dot = (e - S[_V_E]) / dt if has_dt and dt > 0.0 else 0.0
    S[_V_T], S[_V_HAS_T], S[_V_E] = t, 1.0, e
    if code & _VAR_WATCH and has_dt and dt > 0.0 and C[7] != 0.0:
        _oscillation_watch(S, C, dt, p_B)
    g = 1.0 + C[0] * math.tanh(e_dot / C[1])
    g = min(max(g, C[2]), C[3])
    S[_V_G] = g
    gains = C[_V_GAINS:]
    _eq10_at(F, S[_V_H] * g, gains[0:3], gains[3:6], out, 0)
    if code & _VAR_ROTATION:
        _eq10_at(tau, 1.0, gains[6:9], gains[9:12], out, 3)


_NO_POSITION = np.zeros(3)


class KernelVariableAdmittance:
    """`VariableAdmittance`, compiled: the same parameters, state properties (`factor`,
    `stability`, `swings`, `oscillation_m_s`), `reset`, `step` and `step_twist`, the state in one
    array. `step_twist` runs the rotation's eq. 10 in the same call."""

    def __init__(self, params: VariableAdmittanceParams | None = None) -> None:
        warm_up_laws()
        self.state = np.zeros(_V_STATE)
        self.constants = np.zeros(_V_CONSTANTS)
        self._gains: tuple[object, object] | None = None
        self.params = params or VariableAdmittanceParams()
        self.reset()

    @property
    def params(self) -> VariableAdmittanceParams:
        return self._params

    @params.setter
    def params(self, params: VariableAdmittanceParams) -> None:
        self._params = p = params
        self.constants[:_V_GAINS] = (
            p.intent_gain,
            p.intent_rate_per_s,
            p.slope_min,
            p.slope_max,
            p.oscillation_cutoff_hz,
            p.oscillation_window_s,
            p.oscillation_threshold_m_s,
            float(p.oscillation_watch),
            p.oscillation_quiet_s,
            p.oscillation_recover_per_s,
            p.oscillation_min,
            p.oscillation_swings,
        )

    def reset(self) -> None:
        S = self.state
        S[...] = 0.0
        S[_V_G] = S[_V_H] = S[_V_MARGINED] = 1.0

    factor = property(lambda self: float(self.state[_V_G]), doc="g of the last step")
    stability = property(lambda self: float(self.state[_V_H]), doc="h: the watch's factor")
    swings = property(lambda self: float(self.state[_V_C]), doc="c")
    oscillation_m_s = property(lambda self: float(self.state[_V_SIGMA]), doc="σ")

    def _set_gains(self, translation: AdmittanceGains, rotation: AdmittanceGains | None) -> None:
        g = self.constants[_V_GAINS:]
        g[0:3], g[3:6] = translation.slope, translation.deadband
        if rotation is not None:
            g[6:9], g[9:12] = rotation.slope, rotation.deadband

    def step(self, t: float, F: Vec3, slope: Vec3, deadband: Vec3, p_B: Vec3 | None = None) -> Vec3:
        g = self.constants[_V_GAINS:]
        g[0:3], g[3:6] = slope, deadband
        self._gains = None
        out = np.empty(6)
        code = _VAR_WATCH if p_B is not None else 0
        _variable_law(
            self.state, self.constants, t, F, F, _NO_POSITION if p_B is None else p_B, code, out
        )
        return out[:3]

    def step_twist(
        self,
        t: float,
        F: Vec3,
        tau: Vec3,
        translation: AdmittanceGains,
        rotation: AdmittanceGains,
        p_B: Vec3 | None = None,
    ) -> Vec:
        if (
            self._gains is None
            or self._gains[0] is not translation
            or self._gains[1] is not rotation
        ):
            self._set_gains(translation, rotation)
            self._gains = (translation, rotation)
        code = _VAR_WATCH if p_B is not None else 0
        eq10 = rotation.law in ("deadband_linear", "variable")
        if eq10:
            code |= _VAR_ROTATION
        out = np.empty(6)
        _variable_law(
            self.state, self.constants, t, F, tau, _NO_POSITION if p_B is None else p_B, code, out
        )
        if not eq10:
            out[3:] = apply_law(tau, rotation)
        return out


# --- release detection (release.ReleaseDetector) ------------------------------------------------


_RELEASE_NORMS = types.UniTuple(types.float64, 3)(_IN, _IN, _IN, _IN)


@njit(cache=True, nogil=True)
def _release_norms(F, eta, F_raw, band):  # pragma: no cover - compiled
    """‖F ⊘ η‖, ‖F_raw ⊘ b‖ and ‖(F - F_raw) ⊘ b‖ (release.scaled_norm, three times)."""
    gap = np.empty(3)
    for i in range(3):
        gap[i] = F[i] - F_raw[i]
    return _scaled_norm_at(F, eta), _scaled_norm_at(F_raw, band), _scaled_norm_at(gap, band)


class KernelReleaseDetector(ReleaseDetector):
    """`ReleaseDetector` with its two norms a tick in one compiled call."""

    def __init__(self, params: ReleaseParams | None = None) -> None:
        warm_up_laws()
        super().__init__(params)

    def _norms(
        self, F: Vec3, F_raw: Vec3 | None, deadband: Vec3
    ) -> tuple[float, float | None, float | None]:
        if F_raw is None:
            return _release_norms(F, deadband, F, deadband)[0], None, None
        return _release_norms(F, deadband, F_raw, self._band(deadband))


_DEADBAND_LAW6 = types.void(_IN, _IN, _IN, _IN, types.float64[::1])


@njit(cache=True, nogil=True)
def _deadband_law6(F, tau, slope, deadband, out):  # pragma: no cover - compiled
    """admittance.deadband_linear over [F; τ] (eq. 10 per axis, six at once) into `out`: the
    same operations in the same order, so the same bits."""
    for i in range(6):
        x = F[i] if i < 3 else tau[i - 3]
        excess = abs(x) - deadband[i]
        if excess < 0.0:
            excess = 0.0
        sign = 1.0 if x > 0.0 else (-1.0 if x < 0.0 else (x if x != x else 0.0))
        out[i] = sign * slope[i] * excess


def deadband_law6(F: Vec3, tau: Vec3, slope: Vec, deadband: Vec) -> Vec:
    """Eq. 10 on the force and the torque at once, [v; ω] (`admittance.deadband_linear` on
    [F; τ] with six gains): one compiled call instead of seven small numpy ones."""
    out = np.empty(6)
    _deadband_law6(F, tau, slope, deadband, out)
    return out


def warm_up_laws() -> None:
    """Load (or compile) the controller's kernels now (once per process): eq. 10's, the variable
    law's, the release detector's and the passivity controller's. Their blocks call it when they
    are built."""
    if "laws" not in _warm:
        _load(_deadband_law6, _DEADBAND_LAW6)
        _load(_variable_law, _VARIABLE_LAW)
        _load(_release_norms, _RELEASE_NORMS)
        _load(_passivity, _PASSIVITY)
        _warm.add("laws")


def variable_law(
    params: VariableAdmittanceParams | None = None,
) -> VariableAdmittance | KernelVariableAdmittance:
    """The variable law for a controller built now: compiled, or the pure reference."""
    return (KernelVariableAdmittance if kernels_enabled() else VariableAdmittance)(params)


def release_detector(params: ReleaseParams | None = None) -> ReleaseDetector:
    """The release detector for a controller built now: compiled norms, or the pure reference."""
    return (KernelReleaseDetector if kernels_enabled() else ReleaseDetector)(params)


def passivity_controller(
    params: PassivityParams | None = None,
) -> PassivityController | KernelPassivityController:
    """The passivity observer and controller for a controller built now: compiled, or the pure
    reference."""
    return (KernelPassivityController if kernels_enabled() else PassivityController)(params)
