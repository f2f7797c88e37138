"""Error metrics used to identify and validate the model (paper sections 3 and 6).

All functions are pure numpy/scipy and unit-agnostic: they return results in
the units of their inputs (times in s, displacements in mm, forces in N, ...).
The names of the dictionary keys returned by :func:`step_metrics` and
:func:`sine_metrics` carry units, matching the column names of
:mod:`harness.report.tables`.

Metrics
-------
* RMSE between measured and simulated samples (:func:`rmse`), and over the
  gaps that a measured and a simulated sweep have in common (:func:`sweep_rmse`,
  tests T1/T7).
* 2 % settling time of a step response (:func:`settling_time`; vectorized over
  many responses, e.g. an optimizer's population: :func:`settling_times`) and
  the settling-time error STE = |Ts_sim - Ts_meas| (:func:`settling_time_error`),
  tests T2-T5.
* Amplitude ratio and phase shift of a sinusoidal response (:func:`sine_amplitude_phase`,
  :func:`amplitude_ratio_phase_shift`), test T6.

Step-response metrics (settling times, STE, :func:`step_metrics`) live in
:mod:`harness.analysis.core.settling` (the treatment of noisy records is described there), the input
checks and :func:`rmse` in :mod:`harness.analysis.core.signals`; this module is the public API of all
of them.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from harness.analysis.core.settling import (StepLevels, WindowRule, estimate_noise_sigma, resolvable_band, settling_time,
                                       settling_time_error, settling_time_robust, settling_times, smoothing_window_s,
                                       step_metrics)
from harness.analysis.core.signals import as_signals, as_vector, check_frequency, check_same_shape, rmse
from harness.data.protocol import sample_period

__all__ = [
    "StepLevels",
    "WindowRule",
    "rmse",
    "settling_time",
    "settling_time_robust",
    "resolvable_band",
    "settling_times",
    "settling_time_error",
    "smoothing_window_s",
    "estimate_noise_sigma",
    "sine_amplitude_phase",
    "amplitude_ratio_phase_shift",
    "sweep_rmse",
    "step_metrics",
    "sine_metrics",
]

GAP_MATCH_TOL_MM = 1e-9  # gaps closer than this [mm] are the same gap in sweep_rmse


# --------------------------------------------------------------------------- sinusoids
def _wrap(phi: float) -> float:
    """Wrap an angle [rad] to (-pi, pi]."""
    w = math.remainder(phi, 2.0 * math.pi)  # in [-pi, pi]
    return math.pi if w <= -math.pi else w


def sine_amplitude_phase(
    t: Any, y: Any, frequency_hz: float, drift: bool = False, harmonics: int = 1
) -> tuple[float, float]:
    """Least-squares fit ``y ~ c + A sin(2 pi f t + phi) [+ d (t - t_mid)]``.

    Parameters
    ----------
    t : array_like [s]
        Sample times (absolute: the phase refers to t = 0).
    y : array_like [any unit]
        Samples.
    frequency_hz : float [Hz]
        Known frequency f.
    drift : bool
        Also fit a linear drift term.
    harmonics : int
        Also fit sin/cos terms at 2f .. harmonics*f (only the fundamental is
        returned). Over whole periods without drift the harmonics do not affect
        the fundamental; with ``drift=True`` they must be modelled, or harmonic
        content (a response to a raised-cosine drive has a strong 2f term, the
        force going with I^2) leaks through the drift term into A and phi.

    Returns
    -------
    (A, phi)
        Amplitude A >= 0 [unit of y] and phase phi [rad] wrapped to (-pi, pi].
    """
    ta, ya = as_signals(t, min_len=3, y=y)
    check_frequency(frequency_hz)
    if int(harmonics) != harmonics or harmonics < 1:
        raise ValueError(f"harmonics: must be an integer >= 1, got {harmonics!r}")
    w = 2.0 * math.pi * frequency_hz
    cols = [np.sin(w * ta), np.cos(w * ta), np.ones_like(ta)]
    for k in range(2, int(harmonics) + 1):
        cols += [np.sin(k * w * ta), np.cos(k * w * ta)]
    if drift:
        cols.append(ta - 0.5 * (ta[0] + ta[-1]))
    X = np.column_stack(cols)
    if X.shape[0] < X.shape[1]:
        raise ValueError(f"t: {X.shape[0]} samples cannot fit {X.shape[1]} coefficients")
    coef, *_ = np.linalg.lstsq(X, ya, rcond=None)
    a, b = float(coef[0]), float(coef[1])  # a = A cos(phi), b = A sin(phi)
    return float(math.hypot(a, b)), _wrap(math.atan2(b, a))


def _last_periods(t: np.ndarray, frequency_hz: float, periods: int | None) -> np.ndarray:
    """Boolean mask of the last whole periods of the record."""
    T = 1.0 / frequency_hz
    dt = sample_period(t)
    duration = t[-1] - t[0] + dt          # each sample stands for dt of record
    available = int(math.floor(duration / T + 1e-9))
    if periods is None:
        periods = max(available - 1, 1)   # skip the first period (transient)
    if periods < 1:
        raise ValueError(f"periods: must be >= 1, got {periods}")
    if periods > available:
        raise ValueError(
            f"periods: record of {duration:.6g} s holds {available} whole period(s) of "
            f"{frequency_hz:g} Hz, {periods} requested")
    t_start = t[-1] + dt - periods * T
    return t >= t_start - 1e-9 * T


def amplitude_ratio_phase_shift(
    t: Any,
    y_meas: Any,
    y_sim: Any,
    frequency_hz: float,
    periods: int | None = None,
    drift: bool = False,
    harmonics: int = 3,
) -> tuple[float, float]:
    """Amplitude ratio and phase shift of a simulated vs a measured sinusoidal response.

    Both responses are fitted at the fundamental ``frequency_hz`` (see
    :func:`sine_amplitude_phase`; by default with harmonics up to 3f and no
    drift term) over the last ``periods`` whole periods of the record (default:
    all whole periods but the first, to skip the transient).

    Returns
    -------
    (ratio, shift)
        ``A_sim / A_meas`` [-] and ``phi_sim - phi_meas`` [rad] wrapped to
        (-pi, pi]. A positive shift means the simulation leads; the paper's
        T6 values (about -0.2 rad) mean the simulation lags.
    """
    ta, ym, ys = as_signals(t, min_len=3, y_meas=y_meas, y_sim=y_sim)
    check_frequency(frequency_hz)
    sel = _last_periods(ta, frequency_hz, periods)
    a_m, p_m = sine_amplitude_phase(ta[sel], ym[sel], frequency_hz, drift=drift, harmonics=harmonics)
    a_s, p_s = sine_amplitude_phase(ta[sel], ys[sel], frequency_hz, drift=drift, harmonics=harmonics)
    if a_m == 0.0:
        raise ValueError("y_meas: fitted amplitude is zero, amplitude ratio undefined")
    return a_s / a_m, _wrap(p_s - p_m)


# --------------------------------------------------------------------------- sweeps
def sweep_rmse(gap_meas: Any, y_meas: Any, gap_sim: Any, y_sim: Any) -> float:
    """RMSE over the gaps present in both a measured and a simulated sweep (T1, T7).

    Gaps [mm] match when they differ by at most 1e-9 mm. Every measured point
    whose gap is in the simulated sweep counts (measured points at other gaps
    are ignored). Result in the unit of ``y`` (mm for T1, N for T7).

    Raises ValueError if no gap is common, or the simulated gaps are not unique.
    """
    gm = as_vector(gap_meas, "gap_meas")
    ym = as_vector(y_meas, "y_meas")
    gs = as_vector(gap_sim, "gap_sim")
    ys = as_vector(y_sim, "y_sim")
    check_same_shape(gm, ym, "gap_meas", "y_meas")
    check_same_shape(gs, ys, "gap_sim", "y_sim")
    order = np.argsort(gs, kind="stable")
    gs_sorted, ys_sorted = gs[order], ys[order]
    if np.any(np.diff(gs_sorted) <= GAP_MATCH_TOL_MM):
        raise ValueError("gap_sim: gaps must be unique (closer than 1e-9 mm found)")
    idx = np.searchsorted(gs_sorted, gm)
    matched_m, matched_s = [], []
    for k, g in enumerate(gm):
        for cand in (idx[k] - 1, idx[k]):
            if 0 <= cand < gs_sorted.size and abs(gs_sorted[cand] - g) <= GAP_MATCH_TOL_MM:
                matched_m.append(ym[k])
                matched_s.append(ys_sorted[cand])
                break
    if not matched_m:
        raise ValueError("gap_meas and gap_sim have no gap in common (tolerance 1e-9 mm)")
    return rmse(np.array(matched_m), np.array(matched_s))


# --------------------------------------------------------------------------- convenience
def sine_metrics(
    t: Any,
    y_meas: Any,
    y_sim: Any,
    frequency_hz: float,
    periods: int | None = None,
    unit: str = "mm",
) -> dict[str, float]:
    """Fixed-frequency test (T6) metrics over the last whole periods.

    Returns ``amplitude_ratio`` [-] (A_sim/A_meas), ``phase_shift_rad``
    (phi_sim - phi_meas, positive = simulation leads) and ``rmse_<unit>`` over
    the same periods.
    """
    ta, ym, ys = as_signals(t, min_len=3, y_meas=y_meas, y_sim=y_sim)
    ratio, shift = amplitude_ratio_phase_shift(ta, ym, ys, frequency_hz, periods=periods)
    sel = _last_periods(ta, frequency_hz, periods)
    return {
        "amplitude_ratio": float(ratio),
        "phase_shift_rad": float(shift),
        f"rmse_{unit}": rmse(ym[sel], ys[sel]),
    }
