"""Noise estimators on plain arrays (re-exported by :mod:`harness.data.protocol`, which applies them to records).

* :func:`diff_noise`: white-noise std from first or second differences (robust MAD, or RMS when the
  readings are coarsely quantized);
* :func:`tail_noise_floor`: from the high-frequency residual of a record's steady end;
* :func:`sweep_residuals`, :func:`sweep_reading_noise`, :func:`pooled_sweep_reading_noise`: the noise of one
  reading of a gap sweep from the sweep(s) itself.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["diff_noise", "tail_noise_floor", "sweep_residuals", "sweep_reading_noise", "pooled_sweep_reading_noise",
           "QUIET_MIN_SAMPLES"]

QUIET_MIN_SAMPLES = 20      # a quiet part or tail shorter than this gives no noise estimate


def _resolved(d: np.ndarray, mad: float) -> bool:
    """True when the MAD of d is at least 4 spacings of d's distinct values (not coarsely quantized)."""
    u = np.unique(d)
    return bool(mad > 0 and u.size > 1 and mad >= 4.0 * float(np.min(np.diff(u))))


def diff_noise(d: np.ndarray, order: int) -> float:
    """Noise std of white samples from their differences d of the given order (1: var 2 s^2, 2: 6 s^2).

    1.4826 MAD(d) (robust to outliers and steps) when the differences are well resolved (their MAD at
    least 4 times the smallest spacing of their distinct values); otherwise (coarsely quantized
    readings, where the MAD jumps between quantization steps) the RMS of d within 5 robust
    deviations of its median."""
    scale = math.sqrt(2.0 if order == 1 else 6.0)
    med = float(np.median(d))
    mad = float(np.median(np.abs(d - med)))
    if _resolved(d, mad):
        return 1.4826 * mad / scale
    keep = np.abs(d - med) <= 5.0 * max(1.4826 * mad, float(np.std(d)), 1e-300)
    return float(np.sqrt(np.mean((d[keep] - med) ** 2))) / scale


def tail_noise_floor(y, fraction: float = 0.25) -> float | None:
    """Noise floor [unit of y] from the high-frequency residual of the last ``fraction`` of a record
    (its steady end): second differences d2 remove a level and a slope; std = 1.4826 MAD(d2)/sqrt(6)
    (RMS for coarsely quantized readings, as :func:`record_noise_floor`). None below
    :data:`QUIET_MIN_SAMPLES` samples. For records without a quiet part before the step."""
    y = np.asarray(y, dtype=float)
    seg = y[y.size - int(fraction * y.size):]
    if seg.size < QUIET_MIN_SAMPLES:
        return None
    return diff_noise(np.diff(seg, 2), 2)


def sweep_reading_noise(gap_mm, y) -> float | None:
    """Noise std [unit of y] of one reading of a gap sweep, estimated from the sweep itself.

    Each reading with two neighbours on either side is compared with the cubic through those four
    (Lagrange weights w_j at its gap; irregular gap grids allowed): r_i = y_i - sum_j w_j y_j, whose
    variance is s^2 (1 + sum_j w_j^2) for independent readings of noise s (on a uniform grid r is a
    fourth difference / 6). Estimate: 1.4826 MAD of the normalized r (robust to the jump at pull-in
    and the kink at contact; RMS for coarsely quantized readings). A curve that is not locally cubic
    adds to r (an upper estimate on a coarse grid). None with fewer than 7 readings.

    Parameters
    ----------
    gap_mm : array_like
        [mm] gaps of the sweep (any order, distinct).
    y : array_like
        Readings (current [A], displacement [mm] or force [N]), same length.
    """
    r = sweep_residuals(gap_mm, y)
    return None if r is None else _robust_scale(r)


def sweep_residuals(gap_mm, y) -> np.ndarray | None:
    """Normalized deviations r_i (unit of y) of a sweep's readings from the cubic through their four
    neighbours (see :func:`sweep_reading_noise`), None with fewer than 7 readings."""
    g = np.asarray(gap_mm, dtype=float)
    v = np.asarray(y, dtype=float)
    if g.size < 7 or g.shape != v.shape:
        return None
    o = np.argsort(g)
    g, v = g[o], v[o]
    r = []
    for i in range(2, g.size - 2):
        nodes = np.array([i - 2, i - 1, i + 1, i + 2])
        gn = g[nodes]
        w = np.array([np.prod([(g[i] - gn[m]) / (gn[j] - gn[m]) for m in range(4) if m != j]) for j in range(4)])
        r.append((v[i] - w @ v[nodes]) / math.sqrt(1.0 + float(w @ w)))
    return np.asarray(r)


def pooled_sweep_reading_noise(sweeps) -> float | None:
    """Reading noise [unit of y] of several sweeps made with the same sensor (e.g. the T1 of every
    sample): the robust scale of their pooled :func:`sweep_residuals` (11 samples of 26 gaps: about
    240 residuals, a standard error of about 7 % instead of 25 % for one sweep).

    Parameters
    ----------
    sweeps : iterable of (gap_mm, y)
        Pairs of arrays ([mm], readings).
    """
    rs = [r for r in (sweep_residuals(g, y) for g, y in sweeps) if r is not None]
    return _robust_scale(np.concatenate(rs)) if rs else None


#: asymptotic relative standard error of the normal-consistent MAD scale, times sqrt(n): 1.166 / sqrt(n)
MAD_REL_SE = 1.166


def pooled_sweep_reading_noise_rel_sd(sweeps) -> float | None:
    """Relative standard uncertainty of :func:`pooled_sweep_reading_noise` (the MAD scale of its n pooled
    residuals: about 1.166 / sqrt(n)); None when no sweep has the 7 readings it needs. Few gaps give few
    residuals (7 gaps: 3 per sweep), and a scale known only to +-40 % must not read as structure in the data."""
    n = sum(r.size for r in (sweep_residuals(g, y) for g, y in sweeps) if r is not None)
    return MAD_REL_SE / math.sqrt(n) if n else None


def _robust_scale(r: np.ndarray) -> float:
    med = float(np.median(r))
    mad = float(np.median(np.abs(r - med)))
    if _resolved(r, mad):
        return 1.4826 * mad
    keep = np.abs(r - med) <= 5.0 * max(1.4826 * mad, 1e-300) if mad > 0 else np.ones(r.size, bool)
    return float(np.sqrt(np.mean((r[keep] - med) ** 2)))


