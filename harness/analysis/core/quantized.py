"""Residuals of readings that a coarse converter quantized: exact standardization.

A reading is y = Q(x + n): the true value x plus white noise n ~ N(0, sigma^2), rounded to the converter's step q.
For sigma well above q the rounding error is uniform and independent of x, and (y - x) / sqrt(sigma^2 + q^2/12)
is a standard residual (Sheppard's correction: the noise floor). Below about 0.7 q it is not: the mean and the
variance of y depend on where x lies between two steps. At sigma = 0.4 q the variance swings by -13 % .. +13 %
of sigma^2 + q^2/12 over one step, and the mean is off x by up to 0.0135 q. A record that sits on a plateau (a
step test's steady current, thousands of readings at one level) then shows a chi-square several standard
deviations above its count from the rounding alone: a clean 13.5 kHz T2 whose current (sigma 0.4 mA, step 1 mA)
rested 0.27 of a step above a level gave the diagnosis "unexplained" (structure z 5.66; session-15 deep
profile).

:func:`detect` finds the step q from the readings themselves (every reading an integer multiple of the smallest
spacing between distinct readings) and says whether the rounding matters (sigma = sqrt(floor^2 - q^2/12) below
:data:`SIGMA_OVER_Q_MAX` q); :func:`moments` gives, for a true value x, the exact mean mu(x) = sum_k k q P_k and
variance s(x)^2 of the rounded reading (P_k = Phi(((k + 1/2) q - x)/sigma) - Phi(((k - 1/2) q - x)/sigma)), so that
(y - mu(x)) / s(x) has mean square 1 exactly under the noise model, at any x; :func:`reading_weights` evaluates
them at the readings' own level (the weights a least-squares fit can use). Units: whatever unit y, x, sigma and q
share.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

__all__ = ["SIGMA_OVER_Q_MAX", "SIGMA_OVER_Q_MIN", "Quantization", "detect", "moments", "reading_weights"]

#: above this sigma / q the rounding's mean and variance ripple is below 1e-4 of the floor (exp(-2 pi^2 0.7^2))
SIGMA_OVER_Q_MAX = 0.7
#: a noise level below this (a floor that is nearly all rounding) is taken as this, so that s(x) stays positive
SIGMA_OVER_Q_MIN = 0.2


@dataclass(frozen=True)
class Quantization:
    """White noise ``sigma`` and converter step ``q`` of a channel (same unit as its readings)."""
    sigma: float
    q: float


def detect(values, floor: float) -> Quantization | None:
    """The channel's quantization, when its readings lie on a grid and the rounding shapes their noise.

    Parameters
    ----------
    values : array_like
        The channel's readings (finite ones are used).
    floor : float
        Its noise floor sqrt(sigma^2 + q^2/12) (the manifest's, or estimated from the data), same unit.

    Returns
    -------
    Quantization or None
        (sigma, q) with q the smallest spacing of distinct readings when every reading is an integer multiple of
        it (to 1e-6 q) and sigma = sqrt(floor^2 - q^2/12) (at least ``SIGMA_OVER_Q_MIN`` q) is below
        ``SIGMA_OVER_Q_MAX`` q; None otherwise (no grid, too few distinct readings, or noise that hides the
        rounding).

    Examples
    --------
    >>> y = np.array([0.144, 0.145, 0.146, 0.145, 0.147])     # readings of a 1 mA converter [A]
    >>> detect(y, math.sqrt(0.0004 ** 2 + 0.001 ** 2 / 12))
    Quantization(sigma=0.0004, q=0.001)
    >>> detect(y, 0.01) is None                          # noise 10 steps wide: the rounding is invisible
    True
    """
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if not (floor > 0 and math.isfinite(floor)) or v.size < 3:
        return None
    u = np.unique(v)
    if u.size < 3:
        return None
    q = float(np.min(np.diff(u)))
    if not q > 0:
        return None
    k = u / q
    if np.max(np.abs(k - np.rint(k))) > 1e-6 + 1e-12 * float(np.max(np.abs(k))):
        return None
    s2 = floor * floor - q * q / 12.0
    sigma = max(math.sqrt(s2) if s2 > 0 else 0.0, SIGMA_OVER_Q_MIN * q)
    if sigma >= SIGMA_OVER_Q_MAX * q:
        return None
    return Quantization(sigma=round(sigma, 15), q=round(q, 15))


def moments(x, quant: Quantization) -> tuple[np.ndarray, np.ndarray]:
    """(mean, standard deviation) of the rounded reading Q(x + n) for true values x (arrays).

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> x = np.full(200_000, 145.27)
    >>> y = np.rint(x + rng.normal(0, 0.4, x.size))                # sigma 0.4, step 1
    >>> mu, sd = moments(x, Quantization(sigma=0.4, q=1.0))
    >>> round(float(np.mean(((y - mu) / sd) ** 2)), 2)
    1.0
    >>> round(float(np.mean(((y - x) / math.sqrt(0.16 + 1 / 12)) ** 2)), 3)   # the floor alone: 1.4 % high
    1.014
    """
    x = np.asarray(x, dtype=float)
    q, s = quant.q, quant.sigma
    J = int(math.ceil(6.0 * s / q)) + 1
    k0 = np.floor(x / q)
    m1 = np.zeros_like(x)
    m2 = np.zeros_like(x)
    for j in range(-J, J + 1):
        k = k0 + j
        p = ndtr(((k + 0.5) * q - x) / s) - ndtr(((k - 0.5) * q - x) / s)
        d = k * q - x                    # moments about x (no cancellation for large readings)
        m1 += p * d
        m2 += p * d * d
    var = np.maximum(m2 - m1 * m1, 1e-12 * q * q)
    return x + m1, np.sqrt(var)


def reading_weights(y, quant: Quantization, window: int = 101) -> tuple[np.ndarray, np.ndarray]:
    """(offset, scale) per reading for residuals (y - x - offset) / scale: the rounded reading's mean offset and
    standard deviation (:func:`moments`) at the readings' own centred moving mean over ``window`` readings (an
    estimate of the true value that the rounding does not bias by more than 0.0135 q), not at a model's prediction.

    They depend on the data alone, so a least-squares cost stays quadratic in the simulated values: weights that
    follow the prediction x swing by +-6 % each time x crosses a step, and for a model many noise floors off
    that ripple steered the diagnosis's fits (a hidden two-time-constant coil heating named as motional EMF,
    session-15 deep profile). On a plateau the moving mean is the level to within q / sqrt(window), so the
    chi-square keeps the exact mean 1 there; across a step edge the window mixes levels for ``window`` readings."""
    y = np.asarray(y, dtype=float)
    w = max(1, min(int(window), y.size))
    c = np.cumsum(np.r_[0.0, y])
    h = w // 2
    lo = np.clip(np.arange(y.size) - h, 0, y.size)
    hi = np.clip(np.arange(y.size) + h + 1, 0, y.size)
    smooth = (c[hi] - c[lo]) / (hi - lo)
    mu, sd = moments(smooth, quant)
    return mu - smooth, sd
