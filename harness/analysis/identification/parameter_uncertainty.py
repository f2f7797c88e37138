"""Parameter uncertainty of the identified model: a covariance for every identified parameter (R, L, Em,
K1, K2, C, m), nonlinear intervals where the linearization is poor, and random draws for Monte-Carlo
propagation (:mod:`harness.analysis.uncertainty.bands`, the design search).

Where each part comes from (SI units throughout):

* R [Ohm], Em [N.m/T^2], K1 [N/m^3], K2 [N/m]: functions of the seven steady means of the analytic
  identification (:mod:`harness.analysis.identification.analytic`: V5, I5 of T5; F8, I8 of T8; x3, I3 of T3; x5 of T5),
  whose standard uncertainties are std/sqrt(n) of their steady windows (white noise, independent
  tests). Covariance: the Jacobian of (R, Em, K1, K2) with respect to those means (central differences)
  J diag(sd^2) J^T: the four are correlated (K1 and K2 strongly, both through Em). The same
  functions evaluated on normal draws of the means (a parametric bootstrap, ``n_boot`` draws) give
  percentile intervals, which differ from the linear ones where the map is nonlinear: K1 of a small,
  weakly deflected sample is a difference of two nearly equal secant stiffnesses divided by a small
  x5^2 - x3^2.
* L [H]: the RL fit's standard uncertainty (residual variance and Jacobian), independent of the rest.
* C [N.s/m], m [kg]: profile likelihood of the T3 + T5 displacement residuals
  (:mod:`harness.analysis.identification.cm_profile`), with the analytic parameters held at their values, plus the
  analytic parameters' uncertainty propagated into the least-squares C and m, with the cross-covariances
  (:mod:`harness.analysis.identification.cm_joint`: the joint covariance of all seven, ``cov7`` of :func:`combine`); the
  profile intervals are widened by the same factor as the standard deviations.
* a, D (geometry) and a kB from the manifest are treated as known; so is the kernel G (the coil geometry). A
  kB derived from T5 (field_T / I5) is a function of the mean I5: G scales as kB^2, so Em carries twice I5's
  relative uncertainty (correlated with R = V5/I5; K1 and K2, which see only the force Em kB^2 I^2, do not). A
  coil radius a derived from T7 carries its standard uncertainty through G (``res.sd_a_m``).

Draws (:meth:`ParameterUncertainty.draws`) are multivariate normal in log(parameter) with the
covariance transformed to log space, cov_log = cov / (mean mean^T): the parameters stay positive
(K1 = 0 is drawn in linear space and clipped at 0).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from fmu_src.field import make_kernel
from fmu_src.specs import Params
from harness.analysis.identification.analytic import AnalyticResult

__all__ = ["PARAMS", "UncertaintyError", "ParameterUncertainty", "analytic_means", "analytic_map",
           "analytic_covariance", "analytic_bootstrap", "check_map", "combine", "Z95", "AnalyticGeometry",
           "UNCERTAINTY_FORMAT", "uncertainty_to_json", "read_uncertainty"]

PARAMS = ("R", "L", "Em", "K1", "K2", "C", "m")
Z95 = 1.959963984540054          # two-sided 95 % quantile of the standard normal


class UncertaintyError(ValueError):
    """An uncertainty that cannot be computed (singular fit, missing steady values, bad input)."""


# ============================================================================ analytic part
_MEANS = ("V5_V", "I5_A", "F8_N", "I8_A", "x3_m", "I3_A", "x5_m")


def analytic_means(res: AnalyticResult) -> tuple[np.ndarray, np.ndarray]:
    """The seven steady means (V5 [V], I5 [A], F8 [N], I8 [A], x3 [m], I3 [A], x5 [m]) and their standard
    uncertainties from an :class:`harness.analysis.identification.analytic.AnalyticResult`."""
    try:
        s3, s5, s8 = res.steady["T3"], res.steady["T5"], res.steady["T8"]
    except KeyError as e:
        raise UncertaintyError(f"the analytic result has no steady values of {e}") from None
    v = np.array([s5.voltage_V, s5.current_A, s8.response, s8.current_A, s3.response, s3.current_A, s5.response])
    sd = np.array([s5.sd_voltage_V, s5.sd_current_A, s8.sd_response, s8.sd_current_A, s3.sd_response,
                   s3.sd_current_A, s5.sd_response])
    return v, sd


@dataclass(frozen=True, eq=False)
class AnalyticGeometry:
    """What the analytic map needs besides the steady means: a_m, D_m [m], kB [T/A], gaps of T3, T5, T8 [m];
    ``kB_field_T`` [T]: kB was derived from T5 as this field / I5 (None: kB known, from the manifest)."""
    a_m: float
    D_m: float
    kB_T_per_A: float
    gaps_m: tuple
    kB_field_T: float | None = None

    @classmethod
    def of(cls, res: AnalyticResult, gaps_m) -> "AnalyticGeometry":
        derived = getattr(res, "kB_source", "manifest") != "manifest"
        B5 = float(res.kB_T_per_A) * float(res.steady["T5"].current_A) if derived else None
        return cls(float(res.a_m), float(res.D_m), float(res.kB_T_per_A), tuple(float(g) for g in gaps_m), B5)

    @cached_property
    def kernel(self):
        """The force kernel G tabulated up to the largest gap (built once)."""
        return make_kernel(self.a_m, self.D_m, self.kB_T_per_A, max(self.gaps_m))


def analytic_map(v: np.ndarray, geo: AnalyticGeometry) -> np.ndarray:
    """(R [Ohm], Em, K1, K2) of steady means v ((7,) or (n, 7), order of :func:`analytic_means`).

    The analytic identification's formulas: R = V5/I5, Em = F8/(I8^2 G(r8)),
    K1 x^3 + K2 x = Em I^2 G(r0 - x) at T3 and T5 (solved by Cramer's rule, as
    :func:`harness.analysis.identification.analytic.static_stiffness`); G tabulated up to the largest gap.
    """
    v = np.atleast_2d(np.asarray(v, dtype=float))
    V5, I5, F8, I8, x3, I3, x5 = v.T
    g3, g5, g8 = geo.gaps_m
    G = geo.kernel
    # a kB derived from T5 (field / I5) moves with I5; G scales as kB^2, so Em as I5^2 (the forces do not)
    s = 1.0 if geo.kB_field_T is None else (geo.kB_field_T / (I5 * geo.kB_T_per_A)) ** 2
    Em = F8 / (I8 ** 2 * G.eval(np.full_like(F8, g8)) * s)
    F3 = Em * s * I3 ** 2 * G.eval(g3 - x3)
    F5 = Em * s * I5 ** 2 * G.eval(g5 - x5)
    det = x3 ** 3 * x5 - x5 ** 3 * x3
    with np.errstate(divide="ignore", invalid="ignore"):
        K1 = (F3 * x5 - F5 * x3) / det
        K2 = (x3 ** 3 * F5 - x5 ** 3 * F3) / det
    return np.column_stack([V5 / I5, Em, K1, K2])


def analytic_covariance(res: AnalyticResult, gaps_m) -> np.ndarray:
    """(5, 5) covariance of (R, L, Em, K1, K2) [SI units squared] by linear propagation (module docstring).

    gaps_m: the gaps r0 [m] of T3, T5, T8.
    """
    v0, sd = analytic_means(res)
    if not np.all(np.isfinite(sd)) or not np.all(sd >= 0):
        raise UncertaintyError(f"steady means without finite standard uncertainties: {sd.tolist()}")
    geo = AnalyticGeometry.of(res, gaps_m)
    J = np.empty((4, v0.size))
    for i in range(v0.size):
        h = 1e-6 * max(abs(v0[i]), 1e-12)
        dv = np.zeros(v0.size)
        dv[i] = h
        J[:, i] = (analytic_map(v0 + dv, geo)[0] - analytic_map(v0 - dv, geo)[0]) / (2 * h)
    c4 = J @ np.diag(sd ** 2) @ J.T                      # (R, Em, K1, K2)
    sd_a = float(getattr(res, "sd_a_m", 0.0) or 0.0)
    if sd_a > 0:                                          # a derived from the data (T7): through the kernel G
        Ja = radius_sensitivity(res, gaps_m, v0)
        c4 = c4 + sd_a ** 2 * np.outer(Ja, Ja)
    cov = np.zeros((5, 5))
    idx = [0, 2, 3, 4]
    cov[np.ix_(idx, idx)] = c4
    cov[1, 1] = float(res.sd_L_H) ** 2 if math.isfinite(res.sd_L_H) else 0.0
    return cov


def radius_sensitivity(res: AnalyticResult, gaps_m, v0: np.ndarray) -> np.ndarray:
    """d(R, Em, K1, K2)/da [per m] at the steady means v0 (central differences of the analytic map, +-1e-4 a)."""
    geo = AnalyticGeometry.of(res, gaps_m)
    h = 1e-4 * geo.a_m
    up, dn = (analytic_map(v0, replace(geo, a_m=geo.a_m + s * h))[0] for s in (1, -1))
    return (up - dn) / (2 * h)


def analytic_bootstrap(res: AnalyticResult, gaps_m, n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """(n_boot, 4) draws of (R, Em, K1, K2) from normal draws of the steady means (parametric bootstrap); a coil
    radius derived from the data (``res.sd_a_m`` > 0) is drawn too, its effect linearized."""
    v0, sd = analytic_means(res)
    v = v0 + rng.standard_normal((int(n_boot), v0.size)) * sd
    out = analytic_map(v, AnalyticGeometry.of(res, gaps_m))
    sd_a = float(getattr(res, "sd_a_m", 0.0) or 0.0)
    if sd_a > 0:
        out = out + np.outer(rng.standard_normal(int(n_boot)) * sd_a, radius_sensitivity(res, gaps_m, v0))
    return out


def check_map(res: AnalyticResult, gaps_m) -> float:
    """Largest relative difference between :func:`analytic_map` at the steady means and the analytic
    result's own values (a consistency check: both follow the paper's formulas)."""
    v0, _ = analytic_means(res)
    R, Em, K1, K2 = analytic_map(v0, AnalyticGeometry.of(res, gaps_m))[0]
    ref = np.array([res.R_Ohm, res.Em_N_m_per_T2, res.K1_N_per_m3, res.K2_N_per_m])
    got = np.array([R, Em, K1, K2])
    return float(np.max(np.abs(got - ref) / np.maximum(np.abs(ref), 1e-300)))


# ============================================================================ all parameters
@dataclass(frozen=True)
class ParameterUncertainty:
    """Uncertainty of one sample's identified parameters.

    Attributes
    ----------
    sample : str
    wt_pct, diameter_mm : float
        Filler fraction [wt%] and diameter [mm].
    params : Params
        The identified model (the mean of the draws' distribution).
    cov : (7, 7) array
        Covariance of ``PARAMS`` (R, L, Em, K1, K2, C, m) in SI units squared (linearized).
    intervals : dict
        {name: (lo, hi)} 95 % intervals [SI]: bootstrap percentiles (Em, K1, K2, R), profile likelihood
        (C, m), normal (L).
    methods : dict
        {name: how the interval was obtained}.
    """
    sample: str
    wt_pct: float
    diameter_mm: float
    params: Params
    cov: np.ndarray
    intervals: dict = field(default_factory=dict)
    methods: dict = field(default_factory=dict)

    @property
    def mean(self) -> np.ndarray:
        return np.array([float(getattr(self.params, n)) for n in PARAMS])

    @property
    def sd(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.cov), 0.0))

    def log_cov(self) -> tuple[np.ndarray, np.ndarray]:
        """(mask of the parameters drawn in log space, covariance with those rows/columns divided by the mean)."""
        mu = self.mean
        logm = mu > 0
        scale = np.where(logm, np.where(logm, mu, 1.0), 1.0)
        return logm, self.cov / np.outer(scale, scale)

    def draws(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, 7) parameter draws (order ``PARAMS``; module docstring: log-normal, K1 = 0 clipped)."""
        mu = self.mean
        logm, c = self.log_cov()
        z = rng.multivariate_normal(np.zeros(mu.size), c, size=int(n), method="eigh")
        out = np.where(logm, mu * np.exp(z), mu + z)
        return np.maximum(out, 0.0)

    def to_json(self) -> dict:
        from harness.data.paramsjson import KEYS
        keys = [KEYS[n] for n in PARAMS]
        return {"wt_pct": self.wt_pct, "diameter_mm": self.diameter_mm,
                "parameters": {KEYS[n]: float(getattr(self.params, n)) for n in ("a", "D", "kB", *PARAMS)},
                "std": {k + "_std": float(s) for k, s in zip(keys, self.sd)},
                "covariance_order": keys,
                "covariance_SI": self.cov.tolist(),
                "interval_95": {KEYS[n]: [float(v) for v in iv] for n, iv in self.intervals.items()},
                "interval_method": {KEYS[n]: m for n, m in self.methods.items()}}

    @classmethod
    def from_json(cls, sid: str, d: dict) -> "ParameterUncertainty":
        """Inverse of :meth:`to_json` (raises :class:`UncertaintyError` on a bad entry)."""
        from harness.data.paramsjson import KEYS
        inv = {v: k for k, v in KEYS.items()}
        try:
            p = {inv[k]: float(v) for k, v in d["parameters"].items()}
            cov = np.asarray(d["covariance_SI"], dtype=float)
            order = [inv[k] for k in d["covariance_order"]]
            iv = {inv[k]: tuple(float(x) for x in v) for k, v in d.get("interval_95", {}).items()}
            meth = {inv[k]: str(v) for k, v in d.get("interval_method", {}).items()}
            wt, dm = float(d["wt_pct"]), float(d["diameter_mm"])
        except (KeyError, TypeError, ValueError) as e:
            raise UncertaintyError(f"sample {sid}: bad uncertainty entry ({type(e).__name__}: {e})") from None
        if tuple(order) != PARAMS or cov.shape != (7, 7) or not np.all(np.isfinite(cov)):
            raise UncertaintyError(f"sample {sid}: covariance_SI must be a finite 7x7 matrix in the order "
                                   f"{[KEYS[n] for n in PARAMS]}")
        return cls(sample=sid, wt_pct=wt, diameter_mm=dm, params=Params(**p), cov=cov, intervals=iv, methods=meth)


def combine(sample: str, wt_pct: float, diameter_mm: float, params: Params, analytic: tuple, cm: tuple,
            cov7: np.ndarray | None = None) -> ParameterUncertainty:
    """A :class:`ParameterUncertainty` from the analytic part and the (C, m) part.

    analytic: (cov (5, 5) of R, L, Em, K1, K2; bootstrap draws (n, 4) of R, Em, K1, K2);
    cm: (cov (2, 2) of C, m with the analytic parameters held; {"C": (lo, hi), "m": (lo, hi)}
    profile-likelihood intervals[; {"C", "m": the least-squares point}]); cov7: the joint (7, 7)
    covariance (:func:`harness.analysis.identification.cm_joint.least_squares_estimate`; None: block diagonal, the
    analytic parameters' uncertainty not propagated into C, m). With cov7, the C and m intervals are the
    profile's widened about the least-squares point by sqrt(joint variance / profile variance).
    """
    cov5, boot = analytic
    cov_cm, iv_cm = cm[0], cm[1]
    if cov7 is not None:
        cov = np.array(cov7, dtype=float)
        if cov.shape != (7, 7) or not np.all(np.isfinite(cov)):
            raise UncertaintyError(f"sample {sample}: cov7 must be a finite 7x7 matrix, got shape {cov.shape}")
    else:
        cov = np.zeros((7, 7))
        cov[:5, :5] = cov5
        cov[5:, 5:] = cov_cm
    intervals, methods = {}, {}
    for j, n in enumerate(("R", "Em", "K1", "K2")):
        col = boot[:, j]
        col = col[np.isfinite(col)]
        lo, hi = np.percentile(col, [2.5, 97.5])
        # centred on the identified value: the bootstrap's spread around its own median
        med = float(np.median(col))
        v = float(getattr(params, n))
        intervals[n] = (v - (med - lo), v + (hi - med))
        methods[n] = f"parametric bootstrap of the steady means ({col.size} draws), percentiles"
    sdL = math.sqrt(max(cov5[1, 1], 0.0))
    intervals["L"] = (params.L - Z95 * sdL, params.L + Z95 * sdL)
    methods["L"] = "normal, standard uncertainty of the RL fit"
    best = cm[2] if len(cm) > 2 else {}
    for i, n in ((5, "C"), (6, "m")):
        intervals[n] = tuple(iv_cm[n])
        methods[n] = "profile likelihood of the T3 + T5 residuals (chi-square 1 dof, 3.84)"
        if cov7 is not None and n in best and cov_cm[i - 5, i - 5] > 0:
            f = math.sqrt(max(cov[i, i], 0.0) / cov_cm[i - 5, i - 5])
            lo, hi = intervals[n]
            intervals[n] = (best[n] - f * (best[n] - lo), best[n] + f * (hi - best[n]))
            methods[n] += f", widened x{f:.3g} by the analytic parameters' uncertainty (joint covariance)"
        v = float(getattr(params, n))
        if n in best and not (intervals[n][0] <= v <= intervals[n][1]):
            methods[n] += (f"; the identified value lies outside (e.g. the paper's Eq. 6 choice): least-squares "
                           f"point {best[n]:.6g}")
    return ParameterUncertainty(sample=sample, wt_pct=float(wt_pct), diameter_mm=float(diameter_mm), params=params,
                                cov=cov, intervals=intervals, methods=methods)


UNCERTAINTY_FORMAT = "mpc-actuator-uncertainty/1"


def uncertainty_to_json(uncs: dict, unseen: dict | None = None, settings: dict | None = None) -> dict:
    """``uncertainty.json``: {"format", "settings", "samples": {id: ParameterUncertainty.to_json()}, "unseen":
    {id: {"parameters_median": {key: SI}, "std": {key_std: SI}, "interval_95": {key: [lo, hi]}}}} (draws through
    the surfaces: percentiles)."""
    from harness.data.paramsjson import KEYS
    out = {"format": UNCERTAINTY_FORMAT, "settings": dict(settings or {}),
           "samples": {sid: u.to_json() for sid, u in uncs.items()}, "unseen": {}}
    for sid, (base, rows) in (unseen or {}).items():
        lo, hi = np.percentile(rows, [2.5, 97.5], axis=0)
        out["unseen"][sid] = {
            "parameters_median": {KEYS[n]: float(getattr(base, n)) for n in ("a", "D", "kB", *PARAMS)},
            "std": {KEYS[n] + "_std": float(s) for n, s in zip(PARAMS, rows.std(axis=0, ddof=1))},
            "interval_95": {KEYS[n]: [float(a), float(b)] for n, a, b in zip(PARAMS, lo, hi)},
            "draws": int(rows.shape[0])}
    return out


def read_uncertainty(path) -> dict:
    """{id: ParameterUncertainty} of the identified samples in an ``uncertainty.json`` (one clear error line:
    :class:`UncertaintyError` naming the file and what is wrong)."""
    import json
    from pathlib import Path
    p = Path(path)
    try:
        d = json.loads(p.read_text())
    except OSError as e:
        raise UncertaintyError(f"{p}: cannot read ({e.strerror or e})") from None
    except ValueError as e:
        raise UncertaintyError(f"{p}: not JSON ({e})") from None
    if not isinstance(d, dict) or d.get("format") != UNCERTAINTY_FORMAT:
        raise UncertaintyError(f"{p}: not an {UNCERTAINTY_FORMAT} file (written by `mpc-actuator uncertainty`)")
    samples = d.get("samples")
    if not isinstance(samples, dict) or not samples:
        raise UncertaintyError(f"{p}: no samples")
    out = {}
    for sid, e in samples.items():
        try:
            out[sid] = ParameterUncertainty.from_json(sid, e)
        except UncertaintyError as err:
            raise UncertaintyError(f"{p}: {err}") from None
    return out
