"""Covariance and profile-likelihood intervals of the damping C [N.s/m] and the mass m [kg].

The identification chooses C and m on a Pareto front of four objectives (settling-time errors and
RMSEs of T3 and T5, :mod:`harness.analysis.identification.objectives`); their uncertainty here comes from the part
of those objectives that is a likelihood: the sum of squared displacement residuals of T3 and T5,

    SSE(C, m) = n3 RMSE3^2 + n5 RMSE5^2    [m^2],

with the analytic parameters (R, L, Em, K1, K2) held, Gaussian white noise of variance
sigma^2 = SSE_min / (n3 + n5 - 2) (estimated from the fit itself, so that model error widens the
intervals rather than being ignored). The deviance Delta = (SSE - SSE_min) / sigma^2 is evaluated on a
grid in (ln C, ln m) around the best point (two stages: a coarse grid locates it and its scale, a
31 x 31 grid spanning +-4.5 standard deviations of each gives the profile), by one batched run of the
population simulator (:func:`harness.analysis.identification.objectives.evaluate_many`) with tight tolerances.

* point and covariance: from a quadratic fit of SSE over the grid points with Delta < 12: SSE ~ c + b.q +
  q^T A q, the point its centre, cov(ln C, ln m) = sigma^2 A^-1, transformed to SI. The centre must be the
  least-squares point: where the SSE simulated there exceeds the grid's smallest (a likelihood that is not
  quadratic that far out), the fit is repeated nearer the minimum (:data:`CENTRE_TOLERANCE`);
* 95 % profile-likelihood interval of C (of m): the values whose profile deviance (the minimum of
  Delta over the other parameter, refined by a parabola through the three lowest grid points) is at most
  3.84 (chi-square, 1 degree of freedom). It follows the likelihood where it is not quadratic.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from harness.analysis.identification.objectives import CMObjective

__all__ = ["CMProfile", "cm_profile", "profile_interval", "CHI2_95"]

CHI2_95 = 3.841458820694124       # chi-square quantile, 1 degree of freedom, 95 %
_RMSE_COLS = (1, 3)               # T3_rmse_mm, T5_rmse_mm in OBJECTIVE_NAMES order


@dataclass(frozen=True)
class CMProfile:
    """Result of :func:`cm_profile`.

    C_hat [N.s/m], m_hat [kg]: the grid's least-squares point (refined by the quadratic);
    cov: (2, 2) covariance of (C, m) [SI^2]; intervals: {"C": (lo, hi), "m": (lo, hi)} [SI];
    sigma_m: residual standard deviation [m]; lnC, lnm: grid axes; deviance: (n, n) Delta on the grid
    (rows ln C, columns ln m); evaluations: candidates simulated.
    """
    C_hat: float
    m_hat: float
    cov: np.ndarray
    intervals: dict
    sigma_m: float
    lnC: np.ndarray
    lnm: np.ndarray
    deviance: np.ndarray
    evaluations: int

    def to_json(self) -> dict:
        """The estimate, standard deviations, correlation and 95 % intervals with units in the keys."""
        sd = np.sqrt(np.diag(self.cov))
        return {"C_N_s_per_m": self.C_hat, "m_kg": self.m_hat,
                "C_sd_N_s_per_m": float(sd[0]), "m_sd_kg": float(sd[1]),
                "correlation_C_m": float(self.cov[0, 1] / (sd[0] * sd[1])) if sd[0] > 0 and sd[1] > 0 else None,
                "C_interval_95_N_s_per_m": list(self.intervals["C"]), "m_interval_95_kg": list(self.intervals["m"]),
                "residual_sigma_mm": self.sigma_m * 1e3, "evaluations": int(self.evaluations)}


def _sse(obj: CMObjective, lnC: np.ndarray, lnm: np.ndarray) -> np.ndarray:
    n = np.array([meas["t"].size for meas in obj.meas], dtype=float)
    F = obj.evaluate(obj.encode(np.exp(lnC), np.exp(lnm)))
    rm = F[:, list(_RMSE_COLS)] / 1000.0                # [m]
    return (rm ** 2) @ n


def _quad_fit(q: np.ndarray, y: np.ndarray):
    """Least-squares quadratic y ~ c + b.q + q^T A q in 2-D; returns (c, b, A)."""
    u, v = q[:, 0], q[:, 1]
    M = np.column_stack([np.ones_like(u), u, v, u * u, u * v, v * v])
    coef, *_ = np.linalg.lstsq(M, y, rcond=None)
    c, b1, b2, a11, a12, a22 = coef
    return c, np.array([b1, b2]), np.array([[a11, a12 / 2], [a12 / 2, a22]])


def _grid(center, half, n):
    a = np.linspace(center[0] - half[0], center[0] + half[0], n)
    b = np.linspace(center[1] - half[1], center[1] + half[1], n)
    A, B = np.meshgrid(a, b, indexing="ij")
    return a, b, A.ravel(), B.ravel()


def _quadratic_scale(q, sse, n_obs):
    c, b, A = _quad_fit(q, sse)
    if not np.all(np.linalg.eigvalsh(A) > 0):
        return None
    center = -0.5 * np.linalg.solve(A, b)
    smin = c + 0.5 * b @ center
    s2 = max(smin, np.min(sse)) / max(n_obs - 2, 1)
    return center, s2 * np.linalg.inv(A), s2


def profile_interval(axis: np.ndarray, dev: np.ndarray) -> tuple[float, float]:
    """Interval of the axis values whose profile deviance is <= :data:`CHI2_95` (the 95 % profile interval).

    Parameters
    ----------
    axis : ndarray, shape (n,)
        The profiled parameter's grid (here ln C or ln m, ln units), ascending.
    dev : ndarray, shape (n, k)
        Deviance on the grid (rows: ``axis``; columns: the other parameter); +inf at points outside the search
        box (not simulated).

    Returns
    -------
    (lo, hi) : tuple of float
        The interval's ends in ``axis`` units: each row's profile value is the vertex of the parabola through
        its three lowest points (its lowest point beside +inf or at the row's end), the ends are interpolated
        linearly at CHI2_95, and an end at the grid's edge or beside rows wholly outside the box is that row.
    """
    prof = np.empty(dev.shape[0])
    for i, row in enumerate(dev):
        j = int(np.argmin(row))
        y1 = row[j]
        prof[i] = y1
        if 0 < j < row.size - 1 and np.isfinite(row[j - 1]) and np.isfinite(row[j + 1]):
            # parabola through the three lowest points; beside a point outside the search box (+inf: not
            # simulated) the row's minimum within the box is its lowest point (inf / inf gave NaN, which dropped
            # the row from the region: deep profile, session 19)
            y0, y2 = row[j - 1], row[j + 1]
            den = y0 - 2 * y1 + y2
            if den > 0:
                prof[i] = y1 - (y2 - y0) ** 2 / (8 * den)
    inside = np.flatnonzero(prof <= CHI2_95)
    if inside.size == 0:
        k = int(np.argmin(prof))
        return float(axis[k]), float(axis[k])
    lo_i, hi_i = inside[0], inside[-1]

    def cross(i0, i1):
        p0, p1 = prof[i0], prof[i1]
        f = (CHI2_95 - p0) / (p1 - p0) if p1 != p0 else 0.0
        return float(axis[i0] + f * (axis[i1] - axis[i0]))

    lo = cross(lo_i, lo_i - 1) if lo_i > 0 else float(axis[0])
    hi = cross(hi_i, hi_i + 1) if hi_i < axis.size - 1 else float(axis[-1])
    return lo, hi


#: the profile searches (C, m) within the identification's search box (``ObjectiveSettings``: natural frequency
#: f_n = sqrt(K2/m) / 2 pi and damping ratio zeta = C / 2 sqrt(K2 m)) widened by these factors on each side:
#: f_n from f_lo / 4 to 4 f_hi, zeta from zeta_lo / 4 to 4 zeta_hi. Where the residuals hardly change with m (a
#: stiff sample that barely moves under 5x laser noise: deep profile, session 14) the box walked toward m -> 0, where
#: each simulation grows stiff and slow (f_n 330 Hz: 6-9 s a grid), and identify ran for over an hour; now a best
#: point on the widened box's edge ends the search with a ValueError that says so
REGION_FN_FACTOR = 4.0
REGION_ZETA_FACTOR = 4.0


class _Region:
    """The widened search box in (ln C, ln m) of an objective (``obj.xl``, ``obj.xu``: log10 m, log10 zeta bounds;
    ``obj.K2`` [N/m]); objects without them (test doubles) are unbounded."""

    def __init__(self, obj):
        xl, xu, K2 = getattr(obj, "xl", None), getattr(obj, "xu", None), getattr(obj, "K2", None)
        self.bounded = xl is not None and xu is not None and K2 is not None and float(K2) > 0
        if not self.bounded:
            return
        ln10 = np.log(10.0)
        self.K2 = float(K2)
        self.lnm = (float(xl[0]) * ln10 - 2 * np.log(REGION_FN_FACTOR), float(xu[0]) * ln10 + 2 * np.log(REGION_FN_FACTOR))
        self.lnz = (float(xl[1]) * ln10 - np.log(REGION_ZETA_FACTOR), float(xu[1]) * ln10 + np.log(REGION_ZETA_FACTOR))
        self.k = float(np.log(2.0) + 0.5 * np.log(self.K2))      # ln C = k + ln zeta + ln m / 2

    def margin(self, lnC, lnm) -> np.ndarray:
        """Signed distance [ln units] of points to the box (>= 0 inside): the smallest of their distances to the
        bounds of ln m and of ln zeta."""
        lnC, lnm = np.asarray(lnC, dtype=float), np.asarray(lnm, dtype=float)
        if not self.bounded:
            return np.full(np.broadcast(lnC, lnm).shape, np.inf)
        lnz = lnC - self.k - 0.5 * lnm
        return np.minimum.reduce([lnm - self.lnm[0], self.lnm[1] - lnm, lnz - self.lnz[0], self.lnz[1] - lnz])

    def describe(self, lnC: float, lnm: float) -> str:
        m = float(np.exp(lnm))
        f_n = float(np.sqrt(self.K2 / m) / (2 * np.pi))
        zeta = float(np.exp(lnC - self.k - 0.5 * lnm))
        return (f"C {np.exp(lnC):.6g} N.s/m, m {m:.6g} kg: natural frequency {f_n:.4g} Hz, damping ratio {zeta:.3g}; "
                f"the search spans {np.sqrt(self.K2 / np.exp(self.lnm[1])) / (2 * np.pi):.3g}-"
                f"{np.sqrt(self.K2 / np.exp(self.lnm[0])) / (2 * np.pi):.3g} Hz and damping ratios "
                f"{np.exp(self.lnz[0]):.3g}-{np.exp(self.lnz[1]):.3g}")


def _sse_in(obj, region: _Region, lnC: np.ndarray, lnm: np.ndarray) -> np.ndarray:
    """:func:`_sse` of the points inside the region (+inf outside: not simulated)."""
    out = np.full(np.shape(lnC), np.inf)
    ok = region.margin(lnC, lnm) >= 0
    if np.any(ok):
        out[ok] = _sse(obj, lnC[ok], lnm[ok])
    return out


def _check_interior(region: _Region, q: np.ndarray, sse: np.ndarray, step: np.ndarray) -> None:
    """ValueError when the grid's best point lies within one grid step of the region's edge: the residuals keep
    falling toward the edge of the physically searched box, so they do not determine C and m there."""
    if not region.bounded:
        return
    lnC, lnm = q[int(np.argmin(sse))]
    near = min(float(region.margin(lnC + dc, lnm + dm)) for dc in (-step[0], 0.0, step[0])
               for dm in (-step[1], 0.0, step[1]))
    if near < 0:
        raise ValueError("the T3/T5 residuals do not determine C and m: their least-squares point runs to the edge "
                         f"of the search box ({region.describe(lnC, lnm)})")


#: at most this many coarse 9 x 9 grids and fine grids. A start a decade off in m (a small NSGA-II population)
#: walks the coarse box along the narrow C-m valley for more than 12 grids, and the fine stage, doubling its box
#: from 4.5 sd, needed more than 4 recentrings (property test, 905 Hz: "the smallest residuals lie on the edge of
#: the profile grid"); a grid costs 81 (coarse) or n_grid^2 simulations of the two step tests
COARSE_ITERATIONS = 30
FINE_ITERATIONS = 10


#: the reported point is the fitted quadratic's centre only where the SSE simulated there is within this many
#: deviance units of the grid's smallest (on a quadratic likelihood the centre is below it; the fine grid's
#: spacing, 0.3 sd, keeps its best point within about 0.05 of the minimum). Where the likelihood is not
#: quadratic over the fit's Delta < 12 (a mass the T3/T5 data bound from above only: a stiff 20 mm sample under
#: 5x laser noise, deep profile, session 16) the wide fit's centre lay 1.1 from the minimum in ln m (deviance
#: 0.64 above it) and the reported m 2 sd of its own off the least-squares point; then the quadratic is refitted
#: on the points nearer the minimum (Delta below each of REFIT_DEVIANCE in turn), and failing that the grid's
#: best point is reported
CENTRE_TOLERANCE = 0.25
REFIT_DEVIANCE = (4.0, 1.5)


def _fit_at_minimum(obj, region: _Region, q: np.ndarray, sse: np.ndarray, smin: float, s2: float, n_obs: float,
                    fit) -> tuple[tuple, int]:
    """(the quadratic fit whose centre is the least-squares point (:data:`CENTRE_TOLERANCE`), simulations run).
    fit: the fit over the grid's points with Delta < 12; without a better one, the grid's best point with the
    curvature of the last positive definite fit."""
    def deviance_at(c) -> float:
        v = _sse_in(obj, region, np.array([c[0]]), np.array([c[1]]))
        return float((v[0] - smin) / s2)
    n_eval = 1
    if deviance_at(fit[0]) <= CENTRE_TOLERANCE:
        return fit, n_eval
    dev = (sse - smin) / s2
    curvature = fit
    for limit in REFIT_DEVIANCE:
        near = dev < limit
        if near.sum() < 12:
            break
        f = _quadratic_scale(q[near], sse[near], n_obs)
        if f is None:
            continue
        curvature = f
        n_eval += 1
        if deviance_at(f[0]) <= CENTRE_TOLERANCE:
            return f, n_eval
    return (q[int(np.argmin(sse))], curvature[1], curvature[2]), n_eval


def cm_profile(obj: CMObjective, C0: float, m0: float, n_grid: int = 31) -> CMProfile:
    """Covariance and profile-likelihood intervals of (C, m) around the identified (C0, m0) (module docstring).

    obj: the sample's objectives (build it with tight integration tolerances, e.g. settle_rtol 1e-8,
    rk_tol 1e-5: the deviance resolves SSE changes of about 1e-4 relative).
    """
    n_obs = float(sum(meas["t"].size for meas in obj.meas))
    c0 = np.array([np.log(C0), np.log(m0)])
    # stage 1: coarse 9 x 9 grids, +-20 % first, to locate the minimum and the scale. A best point on the
    # box's edge moves the box there (and widens it); an interior one without curvature over the box shrinks
    # the box about it; otherwise the box follows the quadratic's centre (a quadratic over a wide box can put
    # it several sd off the minimum) and shrinks until the centre moves by less than one standard deviation
    evals = 0
    region = _Region(obj)
    center, half = c0, np.array([0.2, 0.2])
    scale = last_good = None
    for _ in range(COARSE_ITERATIONS):
        _, _, a, b = _grid(center, half, 9)
        sse = _sse_in(obj, region, a, b)
        evals += int(np.isfinite(sse).sum())
        q = np.column_stack([a, b])
        if not np.any(np.isfinite(sse)):
            raise ValueError(f"the C/m start lies outside the search box ({region.describe(*center)})")
        _check_interior(region, q, sse, half / 4)
        best = q[int(np.argmin(sse))]
        if np.any(np.isclose(np.abs(best - center), half, rtol=1e-9, atol=0)):
            center, half, scale = best, np.minimum(1.5 * half, 2.0), None
            continue
        fin = np.isfinite(sse)
        scale = _quadratic_scale(q[fin], sse[fin], n_obs) if fin.sum() >= 12 else None
        if scale is None:
            center, half = best, np.maximum(half / 2, 0.01)
            continue
        last_good = (best, scale)
        center_new, cov_ln, _ = scale
        sd = np.sqrt(np.diag(cov_ln))
        moved = np.abs(center_new - center)
        if np.all(moved < half) and np.all(4.5 * sd < 2 * half) and np.all(moved <= sd):
            center = center_new
            break
        center = center_new if np.all(moved < half) else best
        half = np.clip(np.maximum(4.5 * sd, 0.5 * moved), 0.01, 2.0)
    if scale is None and last_good is not None:
        # the iterations ran out while the box was still moving: the last curvature seen sets the fine grid's
        # scale about the best point (the fine stage recentres until the minimum is inside)
        center, scale = last_good
    if scale is None:
        raise ValueError("the T3/T5 residuals do not determine C and m (no curvature around the identified point)")
    sd = np.sqrt(np.diag(scale[1]))
    half = np.clip(4.5 * sd, 1e-4, 3.0)
    for _ in range(FINE_ITERATIONS):
        # fine grid; recentred while the minimum or the 95 % region reaches its edge
        ax_c, ax_m, a, b = _grid(center, half, n_grid)
        sse = _sse_in(obj, region, a, b)
        evals += int(np.isfinite(sse).sum())
        q = np.column_stack([a, b])
        if not np.any(np.isfinite(sse)):
            raise ValueError(f"the C/m profile grid lies outside the search box ({region.describe(*center)})")
        _check_interior(region, q, sse, 2 * half / (n_grid - 1))
        smin = float(np.min(sse))
        s2 = smin / max(n_obs - 2, 1)
        dev = (sse - smin) / s2
        near = dev < 12.0
        fit = _quadratic_scale(q[near], sse[near], n_obs) if near.sum() >= 12 else None
        D2 = dev.reshape(n_grid, n_grid)
        edge = min(D2[0].min(), D2[-1].min(), D2[:, 0].min(), D2[:, -1].min())
        if edge > 2 * CHI2_95:
            break
        k = int(np.argmin(sse))
        if fit is not None:
            center, half = q[k], np.clip(4.5 * np.sqrt(np.diag(fit[1])), 1e-4, 3.0)
            half = np.maximum(half, 1.5 * np.abs(fit[0] - q[k]))
        else:
            center, half = q[k], half * 2
    k = int(np.argmin(sse))
    if k // n_grid in (0, n_grid - 1) or k % n_grid in (0, n_grid - 1):
        # the fine grids ran out with the 95 % region still reaching their edge (else the loop ends earlier) and the
        # best point on it: within the range searched, the data do not pin the point (deep profile, session 18: a
        # stiff 20 mm sample whose deviance changes by under 2 over a factor e^4 toward m -> 0)
        raise ValueError(f"the T3/T5 residuals do not determine C and m: after {FINE_ITERATIONS} profile grids their "
                         f"smallest residuals still lie on the grid's edge, with the 95 % region beyond it "
                         f"(C {np.exp(q[k, 0]):.6g} N.s/m, m {np.exp(q[k, 1]):.6g} kg)")
    if fit is not None:
        fit, n_eval = _fit_at_minimum(obj, region, q, sse, smin, s2, n_obs, fit)
        evals += n_eval
    cov_ln = fit[1] if fit is not None else scale[1]
    ctr = fit[0] if fit is not None else q[int(np.argmin(sse))]
    C_hat, m_hat = float(np.exp(ctr[0])), float(np.exp(ctr[1]))
    D = np.diag([C_hat, m_hat])
    lo_c, hi_c = profile_interval(ax_c, D2)
    lo_m, hi_m = profile_interval(ax_m, D2.T)
    return CMProfile(C_hat=C_hat, m_hat=m_hat, cov=D @ cov_ln @ D,
                     intervals={"C": (float(np.exp(lo_c)), float(np.exp(hi_c))),
                                "m": (float(np.exp(lo_m)), float(np.exp(hi_m)))},
                     sigma_m=float(np.sqrt(s2)), lnC=ax_c, lnm=ax_m, deviance=D2, evaluations=evals)
