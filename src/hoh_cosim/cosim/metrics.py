"""Signal metrics shared by tests, scenarios and the report: lag, noise, attenuation."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from hoh_cosim.errors import ConfigError

__all__ = ["high_passed", "lag_at_frequency", "max_abs", "sinusoid_phase"]


def sinusoid_phase(t: npt.ArrayLike, y: npt.ArrayLike, frequency_hz: float) -> tuple[float, float]:
    """Amplitude and phase φ of the best fit y ≈ A sin(2π f t + φ) + c (least squares)."""
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if t.shape != y.shape or t.ndim != 1 or t.size < 4:
        raise ConfigError(
            f"sinusoid_phase: expected two equal 1-D arrays of >= 4 samples, "
            f"got {t.shape} and {y.shape}"
        )
    w = 2.0 * math.pi * frequency_hz
    A = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    (a, b, _), *_ = np.linalg.lstsq(A, y, rcond=None)
    return math.hypot(a, b), math.atan2(b, a)


def lag_at_frequency(
    t: npt.ArrayLike, reference: npt.ArrayLike, signal: npt.ArrayLike, frequency_hz: float
) -> float:
    """How far [s] `signal` trails `reference` at `frequency_hz`, from the phases of sinusoid fits.

    Positive means late. Valid for lags under half a period; use whole periods of data.
    """
    _, phi_ref = sinusoid_phase(t, reference, frequency_hz)
    _, phi_sig = sinusoid_phase(t, signal, frequency_hz)
    dphi = (phi_ref - phi_sig + math.pi) % (2.0 * math.pi) - math.pi
    return dphi / (2.0 * math.pi * frequency_hz)


def max_abs(x: npt.ArrayLike, axis: int = 0) -> np.ndarray:
    """Largest |x| along `axis`: the seed's "maximum absolute noise" (section 4.C)."""
    return np.max(np.abs(np.asarray(x, dtype=np.float64)), axis=axis)


def high_passed(x: np.ndarray, cutoff_hz: float, dt: float) -> np.ndarray:
    """`x` (n, k) through a 4th-order Butterworth high-pass, forwards and backwards (no phase)."""
    from scipy import signal

    sos = signal.butter(4, cutoff_hz, "highpass", fs=1.0 / dt, output="sos")
    return signal.sosfiltfilt(sos, x, axis=0)
