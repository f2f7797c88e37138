"""Checked signal arrays and the RMSE, shared by the metrics (:mod:`harness.analysis.core.metrics`,
:mod:`harness.analysis.core.settling`).

Every check raises ``ValueError`` naming the offending argument. Unit-agnostic: results are in the
units of the inputs.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["as_vector", "check_same_shape", "as_time", "as_signals", "check_frequency", "rmse",
           "on_grid"]


# --------------------------------------------------------------------------- input checks
def as_vector(x: Any, name: str, *, min_len: int = 1) -> np.ndarray:
    """Return x as a finite 1-D float array or raise ValueError naming ``name``."""
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot convert to a float array ({exc})") from None
    if a.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array, got shape {a.shape}")
    if a.size < min_len:
        if a.size == 0:
            raise ValueError(f"{name}: empty array")
        raise ValueError(f"{name}: need at least {min_len} samples, got {a.size}")
    if not np.all(np.isfinite(a)):
        bad = int(np.flatnonzero(~np.isfinite(a))[0])
        raise ValueError(f"{name}: non-finite value {a[bad]!r} at index {bad}")
    return a


def check_same_shape(a: np.ndarray, b: np.ndarray, name_a: str, name_b: str) -> None:
    if a.shape != b.shape:
        raise ValueError(f"{name_a} and {name_b} differ in shape: {a.shape} vs {b.shape}")


def as_time(t: Any, name: str = "t", *, min_len: int = 2) -> np.ndarray:
    ta = as_vector(t, name, min_len=min_len)
    if np.any(np.diff(ta) <= 0):
        raise ValueError(f"{name}: sample times must be strictly increasing")
    return ta


def as_signals(t: Any, *, min_len: int = 2, **ys: Any) -> tuple[np.ndarray, ...]:
    """(t, y, ...) checked: t strictly increasing with at least ``min_len`` samples, each
    named y (``y_meas=...``) a finite 1-D array of t's shape; errors name the argument."""
    ta = as_time(t, "t", min_len=min_len)
    arrays = [as_vector(y, name) for name, y in ys.items()]
    for name, a in zip(ys, arrays):
        check_same_shape(ta, a, "t", name)
    return (ta, *arrays)


def check_frequency(frequency_hz: float) -> None:
    if not (frequency_hz > 0 and math.isfinite(frequency_hz)):
        raise ValueError(f"frequency_hz: must be positive and finite, got {frequency_hz!r}")


# --------------------------------------------------------------------------- RMSE
def rmse(measured: Any, simulated: Any) -> float:
    """Root-mean-square error sqrt(mean((simulated - measured)^2)).

    Parameters
    ----------
    measured, simulated : array_like, same shape (1-D)
        Samples at the same instants, in the same unit (e.g. mm or N).

    Returns
    -------
    float
        RMSE in the unit of the inputs.

    Raises
    ------
    ValueError
        If an array is empty or holds NaN/inf (the message names the argument),
        or if the shapes differ.
    """
    m = as_vector(measured, "measured")
    s = as_vector(simulated, "simulated")
    check_same_shape(m, s, "measured", "simulated")
    return float(np.sqrt(np.mean((s - m) ** 2)))


# --------------------------------------------------------------------------- convenience
def on_grid(t: np.ndarray, t_sim: Any, y_sim: Any) -> np.ndarray:
    """Simulated samples on the measured time grid (linear interpolation if needed)."""
    ys = as_vector(y_sim, "y_sim")
    if t_sim is None:
        check_same_shape(t, ys, "t", "y_sim")
        return ys
    tsa = as_time(t_sim, "t_sim")
    check_same_shape(tsa, ys, "t_sim", "y_sim")
    if tsa[0] > t[0] + 1e-12 or tsa[-1] < t[-1] - 1e-12:
        raise ValueError("t_sim: must cover the measured time range")
    return np.interp(t, tsa, ys)
