"""The identified (C, m) and the joint covariance of all seven identified parameters.

C [N.s/m] and m [kg] are estimated by least squares on the T3 + T5 displacement residuals (the
profile-likelihood point, :func:`harness.analysis.identification.cm_profile.cm_profile`) *with the analytic parameters
(R, L, Em, K1, K2) held at their identified values*. Those are themselves uncertain
(:func:`harness.analysis.identification.parameter_uncertainty.analytic_covariance`: noise of the steady means, the RL fit), and the
least-squares point moves with them (K1 and K2 most: the spring sets the natural frequency, hence m, and C
with it). The joint covariance of theta = (R, L, Em, K1, K2) and c = (C, m) is, to first order,

    cov(theta) = S,      cov(c) = P + J S J^T,      cov(c, theta) = J S,

with P the profile covariance at fixed theta (the transient residuals' noise, independent of the steady
means' noise to first order) and J = d c_hat / d theta, by central differences of the least-squares point
along the principal axes of S (:func:`propagate`: one standard deviation each way in the parameters'
relative scale; a step clipped at a parameter's lower bound, K1 = 0, becomes one-sided). The matrix is
positive semi-definite by construction: [[S, S J^T], [J S, J S J^T + P]] = [I; J] S [I, J^T] + diag(0, P).

:func:`least_squares_estimate` returns the least-squares JSON (``least_squares``), the joint covariance
(``covariance_7``: parameter keys with units, SI matrix) and 95 % intervals (``interval_95``: normal, for C
and m log-normal) about the least-squares model; :func:`paper_choice_block` describes the paper's Eq. 6 choice against it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from harness.analysis.identification.cm_profile import cm_profile
from harness.analysis.identification.parameter_uncertainty import UncertaintyError, analytic_covariance
from harness.data.paramsjson import KEYS

__all__ = ["CHOICES", "CHOICE_ALIASES", "PARAMS7", "ANALYTIC", "Z95", "propagate", "joint_covariance", "covariance_json", "intervals_95",
           "LOG_NORMAL", "CMEstimate", "least_squares_estimate", "paper_choice_block", "identified_cm", "analytic_covariance_or_none"]

#: IdentifySettings.choice: the (C, m) that becomes the identified model ("eq6": the old name of "paper")
CHOICES = ("least_squares", "paper")
CHOICE_ALIASES = {"eq6": "paper"}
PARAMS7 = ("R", "L", "Em", "K1", "K2", "C", "m")
ANALYTIC = PARAMS7[:5]
Z95 = 1.959963984540054          # two-sided 95 % quantile of the standard normal


def propagate(f: Callable[[np.ndarray], np.ndarray], x0, cov, lower=None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linear propagation of an uncertain x (mean x0, covariance cov) through y = f(x), by central differences.

    The steps are s_i = sqrt(lambda_i) u_i, the principal axes of cov in the relative scale of x0 (so that
    parameters of very different magnitude do not spoil the eigen-decomposition); along each,
    d_i = (f(x0 + s_i) - f(x0 - s_i)) / 2, and to first order y - y0 = sum_i d_i z_i with z_i independent
    standard normals. lower: optional lower bounds of x; a step clipped by a bound is scaled (one-sided
    where a side vanishes). Returns (cov_y = sum d_i d_i^T, cov_yx = sum d_i s_i^T, cov_x = sum s_i s_i^T:
    cov as used, its non-positive eigenvalues dropped). Exact for a linear f.

    Examples
    --------
    >>> A = np.array([[2.0, 0.0], [1.0, 3.0]])
    >>> cy, cyx, _ = propagate(lambda x: A @ x, np.array([1.0, 2.0]), np.diag([0.01, 0.04]))
    >>> np.allclose(cy, A @ np.diag([0.01, 0.04]) @ A.T), np.allclose(cyx, A @ np.diag([0.01, 0.04]))
    (True, True)
    """
    x0 = np.asarray(x0, dtype=float)
    cov = np.asarray(cov, dtype=float)
    n = x0.size
    if cov.shape != (n, n) or not np.all(np.isfinite(cov)):
        raise ValueError(f"cov must be a finite ({n}, {n}) matrix, got shape {cov.shape}")
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    scale = np.where(np.abs(x0) > 0, np.abs(x0), np.where(sd > 0, sd, 1.0))
    lam, U = np.linalg.eigh(cov / np.outer(scale, scale))
    tol = 1e-12 * max(float(lam.max(initial=0.0)), 0.0)
    lo = None if lower is None else np.broadcast_to(np.asarray(lower, dtype=float), (n,))
    cov_y = cov_yx = None
    cov_x = np.zeros((n, n))
    for li, u in zip(lam, U.T):
        if not li > tol:
            continue
        s = scale * math.sqrt(li) * u
        ends, frac = [], []
        for sgn in (1.0, -1.0):
            x = x0 + sgn * s
            if lo is not None:
                x = np.maximum(x, lo)
            ends.append(np.atleast_1d(np.asarray(f(x), dtype=float)))
            frac.append(float((x - x0) @ s) / float(s @ s))       # signed part of the step taken (+-1 unclipped)
        span = frac[0] - frac[1]
        d = (ends[0] - ends[1]) / span if span > 0 else np.zeros_like(ends[0])
        if cov_y is None:
            cov_y, cov_yx = np.zeros((d.size, d.size)), np.zeros((d.size, n))
        cov_y += np.outer(d, d)
        cov_yx += np.outer(d, s)
        cov_x += np.outer(s, s)
    if cov_y is None:                       # no uncertainty at all: f need not be evaluated
        m = np.atleast_1d(np.asarray(f(x0), dtype=float)).size
        cov_y, cov_yx = np.zeros((m, m)), np.zeros((m, n))
    return cov_y, cov_yx, cov_x


def joint_covariance(cov_theta, theta0, cov_fixed, hat_of: Callable[[np.ndarray], np.ndarray],
                     lower=0.0) -> tuple[np.ndarray, np.ndarray]:
    """((k + p) x (k + p) covariance of (theta, c_hat), propagated part J S J^T) (module docstring).

    cov_theta: (k, k) covariance S of the parameters held in the fit; theta0: their values; cov_fixed:
    (p, p) covariance P of c_hat with theta held; hat_of(theta): the estimate c_hat refitted at theta.
    """
    cy, cyx, cx = propagate(hat_of, theta0, cov_theta, lower)
    k, p = cx.shape[0], cy.shape[0]
    P = np.asarray(cov_fixed, dtype=float)
    if P.shape != (p, p):
        raise ValueError(f"cov_fixed must be ({p}, {p}), got {P.shape}")
    out = np.zeros((k + p, k + p))
    out[:k, :k] = cx
    out[k:, :k] = cyx
    out[:k, k:] = cyx.T
    out[k:, k:] = 0.5 * (P + P.T) + cy
    return out, cy


def covariance_json(cov7: np.ndarray, propagated: np.ndarray | None = None) -> dict:
    """``covariance_7``: {"parameters": [keys with units, order R, L, Em, K1, K2, C, m], "matrix": SI,
    "units": ..., "method": ...[, "C_m_propagated_from_analytic": 2 x 2 part J S J^T]}."""
    out = {"parameters": [KEYS[n] for n in PARAMS7], "matrix": np.asarray(cov7, dtype=float).tolist(),
           "units": "SI: entry (i, j) in the unit of parameters[i] times that of parameters[j]",
           "method": "analytic: linear propagation of the steady means' noise and the RL fit; C, m: profile "
                     "likelihood of the T3 + T5 residuals plus the analytic parameters' uncertainty propagated "
                     "by central differences of the least-squares point (cross-covariances included)"}
    if propagated is not None:
        out["C_m_propagated_from_analytic"] = np.asarray(propagated, dtype=float).tolist()
    return out


#: parameters whose 95 % interval is log-normal: C and m are estimated in (ln C, ln m)
#: (:mod:`harness.analysis.identification.cm_profile`) and are positive
LOG_NORMAL = ("C", "m")


def intervals_95(values, cov7: np.ndarray) -> dict:
    """``interval_95``: {key with unit: [lo, hi]} with the joint covariance's sd: R, L, Em, K1, K2 value -+ 1.96 sd
    (normal); C and m value * exp(-+1.96 sd / value) (log-normal: they are estimated in ln C, ln m and are
    positive). The two agree to first order in sd / value; where the data determine m only loosely (sd / value
    near 1: a stiff sample under heavy laser noise, deep profile, session 16) the normal interval reached below
    zero and missed the truth above.

    Examples
    --------
    >>> iv = intervals_95([1.0, 1.0, 1.0, 1.0, 1.0, 2.0, 1e-3], np.diag([0.01] * 5 + [0.0004, 1e-6]))
    >>> [round(x, 4) for x in iv["R_Ohm"]], [round(x, 4) for x in iv["C_N_s_per_m"]]
    ([0.804, 1.196], [1.9612, 2.0396])
    >>> [round(x * 1e3, 4) for x in iv["m_kg"]]          # sd = value: exp(-+1.96)
    [0.1409, 7.0991]
    """
    sd = np.sqrt(np.maximum(np.diag(cov7), 0.0))
    out = {}
    for n, v, s in zip(PARAMS7, values, sd):
        if n in LOG_NORMAL and v > 0:
            out[KEYS[n]] = [float(v * math.exp(-Z95 * s / v)), float(v * math.exp(Z95 * s / v))]
        else:
            out[KEYS[n]] = [float(v - Z95 * s), float(v + Z95 * s)]
    return out


@dataclass(frozen=True)
class CMEstimate:
    """least_squares: :meth:`CMProfile.to_json` or {"error": why}; cov7: (7, 7) joint covariance (None when
    the least-squares point failed); covariance_7, interval_95: their JSON (None likewise); profile: the
    :class:`harness.analysis.identification.cm_profile.CMProfile` at the identified analytic parameters."""
    least_squares: dict
    cov7: np.ndarray | None = None
    covariance_7: dict | None = None
    interval_95: dict | None = None
    profile: object = None

    @property
    def ok(self) -> bool:
        return "error" not in self.least_squares


def least_squares_estimate(make_objective: Callable, params, cov5, C0: float, m0: float,
                           n_grid: int = 11, n_grid_refit: int = 11, nuisance_cov=None) -> CMEstimate:
    """The least-squares (C, m) near (C0, m0) and the joint covariance of the seven parameters.

    make_objective(params): the sample's C/m objectives (:class:`harness.analysis.identification.objectives.CMObjective`,
    tight integration tolerances) for a Params (R, L, Em, K1, K2 of it used); params: the identified
    analytic model; cov5: (5, 5) covariance of R, L, Em, K1, K2 (None: no propagation, the C/m block is the
    profile's alone); n_grid: points per axis of the profile grid, n_grid_refit: of the refits at the
    perturbed analytic parameters (only their least-squares points are used). Never raises for data the
    residuals do not determine: returns {"error": why}.

    nuisance_cov: (q, q) covariance of further held quantities that the residuals depend on and that are
    estimated with an uncertainty of their own (the step instants of T3 and T5, [s^2]), independent of the
    analytic parameters; then make_objective(params, shift) takes their shift from the held values (a length-q
    array; zeros: the held values) too, their uncertainty is propagated into C and m like the analytic
    parameters' (the same central differences), and the seven-parameter covariance is its marginal (the
    cross-covariances of C, m with R .. K2 unchanged).
    """
    Q = None if nuisance_cov is None else np.atleast_2d(np.asarray(nuisance_cov, dtype=float))
    q = 0 if Q is None else Q.shape[0]
    make = make_objective if Q is None else (lambda p, shift=np.zeros(q): make_objective(p, shift))
    try:
        prof = cm_profile(make(params), C0, m0, n_grid=n_grid)
    except (ValueError, np.linalg.LinAlgError) as e:
        return CMEstimate({"error": str(e)})
    ls = prof.to_json()
    theta0 = np.array([float(getattr(params, n)) for n in ANALYTIC])
    if cov5 is None:
        cov7, prop = np.zeros((7, 7)), None
        cov7[5:, 5:] = prof.cov
    else:
        def hat_of(theta):
            p = params.with_(**dict(zip(ANALYTIC, (float(v) for v in theta[:5]))))
            obj = make(p) if Q is None else make(p, np.asarray(theta[5:], dtype=float))
            pr = cm_profile(obj, prof.C_hat, prof.m_hat, n_grid=n_grid_refit)
            return np.array([pr.C_hat, pr.m_hat])
        try:
            if Q is None:
                cov7, prop = joint_covariance(cov5, theta0, prof.cov, hat_of)
            else:
                S = np.zeros((5 + q, 5 + q))
                S[:5, :5], S[5:, 5:] = cov5, Q
                lower = np.r_[np.zeros(5), np.full(q, -np.inf)]          # shifts have no bound
                full, prop = joint_covariance(S, np.r_[theta0, np.zeros(q)], prof.cov, hat_of, lower)
                keep = np.r_[np.arange(5), 5 + q + np.arange(2)]
                cov7 = full[np.ix_(keep, keep)]
        except (ValueError, np.linalg.LinAlgError) as e:
            ls["propagation_error"] = f"the analytic parameters' uncertainty was not propagated: {e}"
            cov7, prop = np.zeros((7, 7)), None
            cov7[:5, :5] = cov5
            cov7[5:, 5:] = prof.cov
    values = [*theta0, prof.C_hat, prof.m_hat]
    return CMEstimate(ls, cov7, covariance_json(cov7, prop), intervals_95(values, cov7), prof)


def paper_choice_block(C: float, m: float, index: int, est: CMEstimate) -> dict:
    """``paper_choice``: the Eq. 6 model's C, m, its front index and its deviation from the least-squares
    estimate in standard deviations (of the joint covariance; the profile's if that is missing)."""
    out = {"C_N_s_per_m": float(C), "m_kg": float(m), "pareto_index": int(index),
           "note": "the paper's Eq. 6 choice on the Pareto front (min-max normalized settling-time errors and "
                   "RMSEs): a design compromise, not an estimator; on clean data it lies several standard "
                   "deviations from the least-squares estimate (measured: 1.6 to 8 times the noise bounds)"}
    ls = est.least_squares
    if not est.ok:
        return out
    if est.cov7 is not None:
        sdC, sdm = (math.sqrt(max(est.cov7[i, i], 0.0)) for i in (5, 6))
    else:
        sdC, sdm = ls["C_sd_N_s_per_m"], ls["m_sd_kg"]
    out["C_deviation_sd"] = (float(C) - ls["C_N_s_per_m"]) / sdC if sdC > 0 else None
    out["m_deviation_sd"] = (float(m) - ls["m_kg"]) / sdm if sdm > 0 else None
    out["C_deviation_pct"] = 100.0 * (float(C) / ls["C_N_s_per_m"] - 1.0)
    out["m_deviation_pct"] = 100.0 * (float(m) / ls["m_kg"] - 1.0)
    return out


def identified_cm(choice: str, est: CMEstimate, C: float, m: float, index: int) -> tuple[float, float, str, dict]:
    """(C, m, the choice used, ``paper_choice``) of the identified model: choice "least_squares" takes the
    least-squares estimate, "paper" the Eq. 6 model (C, m, index on the front); a failed least-squares
    estimate falls back to the paper's choice, the reason recorded as ``paper_choice["fallback"]``."""
    paper = paper_choice_block(C, m, index, est)
    if choice == "least_squares" and est.ok:
        return est.least_squares["C_N_s_per_m"], est.least_squares["m_kg"], choice, paper
    if choice == "least_squares":
        paper["fallback"] = (f"the least-squares estimate failed ({est.least_squares['error']}): the paper's "
                             f"Eq. 6 choice is the identified model")
    return float(C), float(m), "paper", paper


def analytic_covariance_or_none(result, gaps_m) -> np.ndarray | None:
    """:func:`harness.analysis.identification.parameter_uncertainty.analytic_covariance`, or None where it cannot be computed."""
    try:
        cov = analytic_covariance(result, gaps_m)
    except (UncertaintyError, ValueError, np.linalg.LinAlgError):
        return None
    return cov if np.all(np.isfinite(cov)) else None
