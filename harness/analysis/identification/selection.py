"""Choosing one model from the identification's Pareto front (paper Eq. 6) and checking the choice
against the displacement residuals.

* :func:`validate_weights`, :func:`select_by_weights`: Eq. 6, J = sum_i alpha_i * Jbar_i over the four
  objectives (T3 STE, T3 RMSE, T5 STE, T5 RMSE), min-max normalized over the front;
* :func:`residual_check`: the chosen model's residual deviance against the front's least-squares model
  (Eq. 6 is a design choice, not an estimator; the check says when the residuals reject the choice).

Used by :mod:`harness.analysis.identification.identify` (which re-exports these names).
"""
from __future__ import annotations

import math

import numpy as np

from harness.analysis.identification.objectives import OBJECTIVE_NAMES

__all__ = ["validate_weights", "select_by_weights", "residual_check", "CHI2_95_2DOF"]


def validate_weights(weights) -> tuple[float, float, float, float]:
    """Check Eq. 6 weights: four finite numbers >= 0, not all zero. Returns them as floats."""
    try:
        w = [float(v) for v in weights]
    except (TypeError, ValueError):
        raise ValueError(f"weights must be 4 numbers (alpha for {', '.join(OBJECTIVE_NAMES)}), "
                         f"got {weights!r}") from None
    if len(w) != 4:
        raise ValueError(f"weights must be 4 numbers (alpha for {', '.join(OBJECTIVE_NAMES)}), got {len(w)}")
    if not all(math.isfinite(v) and v >= 0 for v in w):
        raise ValueError(f"weights must be finite and >= 0, got {w}")
    if sum(w) == 0:
        raise ValueError("weights must not all be zero")
    return tuple(w)


def select_by_weights(F, weights=(1.0, 1.0, 1.0, 1.0)) -> tuple[int, np.ndarray]:
    """Eq. 6: index of the model with the smallest J = sum_i alpha_i * Jbar_i, and J for every model.

    Jbar_i = (F_i - min F_i) / (max F_i - min F_i) over the given front (0 where the front
    is flat in that objective). Ties go to the first index.
    """
    w = np.asarray(validate_weights(weights))
    F = np.asarray(F, dtype=float)
    if F.ndim != 2 or F.shape[1] != 4 or F.shape[0] == 0:
        raise ValueError(f"F must be an (n >= 1, 4) array of objectives, got shape {F.shape}")
    lo = F.min(axis=0)
    span = F.max(axis=0) - lo
    Jbar = np.where(span > 0, (F - lo) / np.where(span > 0, span, 1.0), 0.0)
    J = Jbar @ w
    return int(np.argmin(J)), J


#: chi-square 95 % quantile, 2 degrees of freedom (C and m): the deviance the residuals allow
CHI2_95_2DOF = 5.991464547107979


def residual_check(F, n_points, k: int, C, m) -> dict:
    """How far the residuals put the chosen front model from the front's least-squares model.

    Eq. 6 balances settling-time errors and RMSEs; it is a design choice, not an estimator, and on noisy
    records the settling-time objectives can pull it away from the C and m the displacement residuals
    support. The sum of squared residuals of T3 and T5 is SSE = n3 RMSE3^2 + n5 RMSE5^2 (n3, n5: samples
    of each record, ``n_points``); with sigma^2 = SSE_min / (n3 + n5 - 2) over the front, the deviance of
    model i is (SSE_i - SSE_min) / sigma^2. Models with deviance above the chi-square 95 % quantile for two
    parameters (5.99) are rejected by the residuals at 95 %, as if their C and m were fitted by least
    squares with white noise (the chosen model's deviance is reported either way).

    F: (n, 4) front objectives in OBJECTIVE_NAMES order (RMSEs in mm); k: the chosen index; C [N.s/m], m
    [kg]: the front's models. Returns a JSON-ready dict (units in the keys).

    Examples
    --------
    >>> F = np.array([[0.0, 1.0, 0.0, 1.0], [0.0, 1.1, 0.0, 1.0]])       # RMSE3 10 % higher in model 1
    >>> r = residual_check(F, [100, 100], 1, [1.0, 2.0], [0.1, 0.2])
    >>> round(r["chosen_deviance"], 2), r["chosen_consistent_with_residuals"]   # 100*0.21/(200/198)
    (20.79, False)
    """
    F = np.asarray(F, dtype=float)
    n3, n5 = (float(n) for n in n_points)
    sse = n3 * (F[:, 1] * 1e-3) ** 2 + n5 * (F[:, 3] * 1e-3) ** 2       # [m^2]
    i = int(np.argmin(sse))
    s2 = sse[i] / max(n3 + n5 - 2.0, 1.0)
    dev = (sse - sse[i]) / s2 if s2 > 0 else np.zeros_like(sse)
    return {"chosen_deviance": float(dev[k]), "deviance_limit_95": CHI2_95_2DOF,
            "chosen_consistent_with_residuals": bool(dev[k] <= CHI2_95_2DOF),
            "front_models_consistent": int(np.count_nonzero(dev <= CHI2_95_2DOF)),
            "least_squares_front_model": {"index": i, "C_N_s_per_m": float(np.asarray(C)[i]),
                                          "m_kg": float(np.asarray(m)[i])},
            "residual_sigma_mm": float(np.sqrt(s2) * 1e3)}
