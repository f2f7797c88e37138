"""Parameter identification of one MPC diaphragm actuator (paper section 3).

Numerics only (no plotting). Per sample, from the measured tests T3, T5 (displacement
steps at 0.11 T and 0.23 T) and T8 (blocked-force step at 0.23 T, gap 2 mm); steps 1-4 are
:mod:`harness.analysis.analytic` (the one implementation, shared with the diagnosis):

1. Coil, from the T5 current: R = V_ss / I_ss over the steady part [Ohm]; L [H] by a
   least-squares fit (``scipy.optimize.least_squares``) of the exact RL response to
   the measured voltage (zero-order hold, as the simulator applies it) to the
   measured current from the step on.
2. Field per ampere kB [T/A]: the manifest's ``rig.field_per_amp_T_per_A``, else
   ``field_T`` of T5 divided by the steady T5 current. Loop radius a [m]: the
   manifest's ``rig.coil_radius_mm`` (required). Diameter D [m]: the sample's.
3. Em [N.m/T^2] from T8: Em = F_ss / (I_ss^2 * G(gap_T8)) (blocked diaphragm, x = 0).
4. K1 [N/m^3], K2 [N/m] from the steady displacements of T3 and T5: the static balance
   K1*x^3 + K2*x = Em*I^2*G(r0 - x) written for both tests is a 2x2 linear system.
5. C [N.s/m] and m [kg] by NSGA-II (pymoo) with four objectives, the 2 % settling-time
   error [s] and the RMSE [mm] of T3 and of T5 between measured and simulated
   displacement. The whole Pareto front is kept; one model is chosen by the paper's
   Eq. 6, J = sum_i alpha_i * Jbar_i, with Jbar_i the objectives min-max normalized over
   the front (equal weights by default).

Steady values are means over the last ``steady_fraction`` of the record after the step
(the measured response must have settled before that part starts).

Simulations for the optimization use :mod:`harness.sim.population`: the current is computed once
per test from the measured voltage with the identified R and L, and the mechanical part
of a whole population (of several samples when :func:`identify_dataset` runs them
together) is integrated at once.

Objectives, judged as :func:`harness.analysis.metrics.step_metrics` judges a simulation when the
sensor noise is known (the validation tables use the same functional):

* RMSE [mm] over every sample of the record;
* STE [s] = |Ts_sim - Ts_meas|, 2 % settling times with the centered moving mean of
  :func:`harness.analysis.metrics.smoothing_window_s` applied alike to the measured and the
  simulated response and the final level estimated on the settled part
  (:func:`harness.analysis.metrics.settling_time_robust` for the measured record; for the
  population a vectorized equivalent of ``metrics.settling_times(..., settled_final=True)``
  on the compact batch result, tested equal). A simulation that never settles within the
  record gets Ts = end of record (STE stays finite and ordered). STE is rounded to
  ``ste_resolution_s`` (default: the sample period): settling times are not resolved
  below one sample, and without the rounding models whose settling times match the
  noisy measured ones to a fraction of a millisecond, however poor their RMSE, end up on
  the front and dominate the min-max normalization of Eq. 6.

Search space: the small-signal natural frequency f_n = sqrt(K2/m)/(2 pi) and damping
ratio zeta = C / (2 sqrt(K2 m)) span ``f_n_range_hz`` and ``zeta_range``; i.e.
m in [K2/(2 pi f_hi)^2, K2/(2 pi f_lo)^2] and, for each m, C in
[2 zeta_lo sqrt(K2 m), 2 zeta_hi sqrt(K2 m)]. NSGA-II (pymoo's NSGA2, seeded; duplicates
are not eliminated, candidates already evaluated are looked up instead of re-simulated)
works on (log10 m, log10 zeta), the bounds being derived from the identified K2 (a
parallelogram in log C - log m; a plain box in (C, m) would include absurdly stiff
corners such as zeta = 500).

Bad data raise :class:`IdentificationError` (a ``ValueError``) naming the sample and
the test.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from harness.sim import population
from harness.sim.results import BatchResult
from harness.sim.settings import MechParams, PopulationSettings
from fmu_src.params import SPEC_BY_NAME, Params
from harness.analysis import metrics
from harness.analysis.analytic import (AnalyticError, AnalyticInput, AnalyticOptions, AnalyticResult, SteadyState,
                                       StepTest, analytic_identification, steady_state)
from harness.data import paramsjson

__all__ = [
    "IdentificationError", "IdentifySettings", "SampleIdentification", "ParetoFront",
    "identify_sample", "identify_dataset", "identification_to_json", "write_identification",
    "select_by_weights", "validate_weights", "non_dominated", "training_samples", "identify_and_write",
    "OBJECTIVE_NAMES", "REQUIRED_TESTS",
]

REQUIRED_TESTS = ("T3", "T5", "T8")
# Order of the objectives (paper Eq. 6: alpha_1..alpha_4).
OBJECTIVE_NAMES = ("T3_ste_s", "T3_rmse_mm", "T5_ste_s", "T5_rmse_mm")

# The identified parameters (the paper's, without the per-test gap r0): JSON key with unit, unit.
PARAM_KEYS = {n: paramsjson.KEYS[n] for n in paramsjson.PAPER}
PARAM_UNITS = {n: SPEC_BY_NAME[n].unit for n in PARAM_KEYS}


class IdentificationError(ValueError):
    """Data that cannot be identified; the message names the sample and the test."""

    def __init__(self, sample: str, test: str | None, message: str):
        self.sample, self.test, self.reason = sample, test, message
        where = f"sample {sample}" + (f", test {test}" if test else "")
        super().__init__(f"{where}: {message}")


# ============================================================================ settings
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


@dataclass(frozen=True)
class IdentifySettings:
    """Settings of the identification.

    pop_size, n_gen: NSGA-II population size and generations (paper: 200 and 200, see
    :meth:`paper`; the default 64 x 60 reaches the same chosen model, see the tests).
    seed: random seed of NSGA-II (each sample's run is seeded alike and is independent of
    the other samples). weights: Eq. 6 weights alpha_1..alpha_4 for (T3 STE, T3 RMSE,
    T5 STE, T5 RMSE). f_n_range_hz [Hz], zeta_range [-]: search space (module docstring).
    band: settling band (0.02 = 2 %). steady_fraction: part of the post-step record
    averaged for steady values. ste_resolution_s [s]: settling-time errors are rounded to
    this resolution (default: the sample period, below which settling times are not
    resolved; without it, differences of a fraction of a millisecond between noisy
    measured and simulated settling times put far-off models on the front and decide
    Eq. 6). settle_rtol, rk_tol: tolerances of the batched integration
    (:func:`harness.sim.population.integrate`).
    """
    pop_size: int = 64
    n_gen: int = 60
    seed: int = 1
    weights: tuple = (1.0, 1.0, 1.0, 1.0)
    f_n_range_hz: tuple = (1.0, 100.0)
    zeta_range: tuple = (0.05, 5.0)
    band: float = 0.02
    steady_fraction: float = 0.5
    settle_rtol: float = 1e-4
    rk_tol: float = 1e-3
    ste_resolution_s: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "weights", validate_weights(self.weights))
        if int(self.pop_size) != self.pop_size or self.pop_size < 4:
            raise ValueError(f"pop_size must be an integer >= 4, got {self.pop_size!r}")
        if int(self.n_gen) != self.n_gen or self.n_gen < 1:
            raise ValueError(f"n_gen must be an integer >= 1, got {self.n_gen!r}")
        for name in ("f_n_range_hz", "zeta_range"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (0 < lo < hi and math.isfinite(hi)):
                raise ValueError(f"{name} must be (lo, hi) with 0 < lo < hi, got {getattr(self, name)!r}")
            object.__setattr__(self, name, (lo, hi))
        if not (0 < self.band < 1):
            raise ValueError(f"band must be in (0, 1), got {self.band!r}")
        if not (0 < self.steady_fraction <= 0.9):
            raise ValueError(f"steady_fraction must be in (0, 0.9], got {self.steady_fraction!r}")

    @classmethod
    def paper(cls, **kw) -> "IdentifySettings":
        """The paper's NSGA-II settings: population 200, 200 generations."""
        return cls(pop_size=200, n_gen=200, **kw)

    def to_json(self) -> dict:
        return {"pop_size": int(self.pop_size), "n_gen": int(self.n_gen), "seed": int(self.seed),
                "weights": {n: w for n, w in zip(OBJECTIVE_NAMES, self.weights)},
                "f_n_range_Hz": list(self.f_n_range_hz), "zeta_range": list(self.zeta_range),
                "settling_band": self.band, "steady_fraction": self.steady_fraction,
                "settle_rtol": self.settle_rtol, "rk_tol": self.rk_tol,
                "ste_resolution_s": self.ste_resolution_s}


# ============================================================================ results
@dataclass
class ParetoFront:
    """Non-dominated models: C [N.s/m], m [kg], objectives (n, 4) in OBJECTIVE_NAMES order."""
    C: np.ndarray
    m: np.ndarray
    objectives: np.ndarray

    def __len__(self):
        return int(self.C.size)


@dataclass
class SampleIdentification:
    """Identification result of one sample.

    ``params``: the identified model (r0 is a per-test setting and left at its default,
    blocked False). ``values``: {name: (value, unit)}. ``uncertainty``: standard
    uncertainty of R, L, Em, K1, K2 from the measurement noise (same units).
    ``steady``: steady-state values used. ``pareto``: the whole front; ``chosen``: its
    index picked by Eq. 6; ``chosen_objectives``: {objective name: value} plus "J".
    ``timing_s``: wall times of the analytic part and of the optimization.
    """
    sample: str
    wt_pct: float
    diameter_mm: float
    params: Params
    values: dict
    uncertainty: dict
    steady: dict
    pareto: ParetoFront
    chosen: int
    chosen_objectives: dict
    J: np.ndarray
    weights: tuple
    bounds: dict
    timing_s: dict
    settings: IdentifySettings | None = None
    evaluations: int = 0


# ============================================================================ helpers
def _rig_get(rig, key):
    if rig is None:
        return None
    if hasattr(rig, "rig") and isinstance(getattr(rig, "rig"), dict):   # a Dataset
        rig = rig.rig
    v = rig.get(key) if isinstance(rig, dict) else None
    return None if v is None else float(v)


def _noise_sigma(rig, column: str):
    if hasattr(rig, "rig") and isinstance(getattr(rig, "rig"), dict):
        rig = rig.rig
    try:
        return float(rig["sensors"][column]["noise_sigma"])
    except (KeyError, TypeError, ValueError):
        return None


def _step_test(sid, ts, col: str) -> StepTest:
    """A dataset time series as the analytic identification's StepTest (response in m or N)."""
    y = getattr(ts, col)
    if y is None:
        raise IdentificationError(sid, ts.test, f"no {col} column")
    field_T = getattr(ts, "field_T", None)
    return StepTest(name=ts.test, time_s=ts.time_s, voltage_V=ts.voltage_V, current_A=ts.current_A,
                    response=y / 1000.0 if col == "displacement_mm" else y, gap_m=float(ts.gap_mm) / 1000.0,
                    field_T=float("nan") if field_T is None else float(field_T), response_name=col)


def _settling_checked(sid, ts, col: str, st: SteadyState, settings: IdentifySettings, noise_sigma) -> float:
    """2 % settling time [s] of the measured response; it must settle before the steady window starts."""
    t, y = ts.time_s, getattr(ts, col)
    try:
        ts_meas = metrics.settling_time_robust(t, y, t_step=st.t_step_s, noise_sigma=noise_sigma,
                                               band=settings.band)
    except ValueError as e:
        raise IdentificationError(sid, ts.test, f"settling time of {col}: {e}") from None
    if not math.isfinite(ts_meas) or st.t_step_s + ts_meas > t[st.start]:
        raise IdentificationError(
            sid, ts.test, f"the {col} step never settles within the record (2 % settling time "
                          f"{'none' if not math.isfinite(ts_meas) else f'{ts_meas:.3g} s'}; the steady part "
                          f"starts {t[st.start] - st.t_step_s:.3g} s after the step)")
    return float(ts_meas)


def _require_tests(sample) -> None:
    missing = [n for n in REQUIRED_TESTS if n not in sample.tests]
    if missing:
        raise IdentificationError(sample.id, ", ".join(missing),
                                  f"missing test{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
                                  f"(identification needs T3, T5 and T8; the sample has "
                                  f"{', '.join(sample.tests) or 'none'})")
    for n in REQUIRED_TESTS:
        ts = sample.tests[n]
        if not hasattr(ts, "time_s"):
            raise IdentificationError(sample.id, n, "expected a time series")


# ============================================================================ analytic part
@dataclass(frozen=True, eq=False)
class SampleAnalytic:
    """The analytic part of one sample's identification.

    sid, wt_pct [wt%]; params: R, L, kB, Em, K1, K2 (C, m at their defaults); result: the
    :class:`harness.analysis.analytic.AnalyticResult`; steady: steady values for the JSON (units in
    the keys); uncertainty: {name: standard uncertainty}; tests: {"T3", "T5": TimeSeries};
    settling_s: {"T3", "T5", "T8": 2 % settling time [s] of the measured response}.
    """
    sid: str
    wt_pct: float
    params: Params
    result: AnalyticResult
    steady: dict
    uncertainty: dict
    tests: dict
    settling_s: dict

    @property
    def st(self) -> dict:
        """{"T3", "T5", "T8": SteadyState}."""
        return self.result.steady


_COLUMNS = {"T3": "displacement_mm", "T5": "displacement_mm", "T8": "force_N"}


def analyse_sample(sample, rig, settings: IdentifySettings) -> SampleAnalytic:
    """The analytic part (R, L, kB, Em, K1, K2) of one sample, checked for identification.

    sample: :class:`harness.data.dataset.Sample`; rig: the manifest's ``rig`` (or the Dataset).
    Besides :func:`harness.analysis.analytic.analytic_identification`'s checks, every step
    response must settle before its steady window. Raises :class:`IdentificationError`.
    """
    sid = sample.id
    _require_tests(sample)
    a_mm = _rig_get(rig, "coil_radius_mm")
    if a_mm is None or not (a_mm > 0):
        raise IdentificationError(sid, None, "the dataset manifest has no rig.coil_radius_mm (the loop radius a "
                                             "of the electromagnet is needed for the field model)")
    D = float(sample.diameter_mm) / 1000.0
    if not (D > 0):
        raise IdentificationError(sid, None, f"diameter_mm must be > 0, got {sample.diameter_mm!r}")
    options = AnalyticOptions(steady_fraction=settings.steady_fraction)
    tests, settling = {}, {}
    try:
        for name in REQUIRED_TESTS:
            ts, col = sample.tests[name], _COLUMNS[name]
            tests[name] = _step_test(sid, ts, col)
            st = steady_state(tests[name], settings.steady_fraction)
            settling[name] = _settling_checked(sid, ts, col, st, settings, _noise_sigma(rig, col))
        res = analytic_identification(AnalyticInput(T3=tests["T3"], T5=tests["T5"], T8=tests["T8"], a_m=a_mm / 1000.0,
                                                     D_m=D, kB_T_per_A=_rig_get(rig, "field_per_amp_T_per_A")),
                                      options)
    except AnalyticError as e:
        raise IdentificationError(sid, e.test, e.reason) from None
    s3, s5, s8 = (res.steady[n] for n in REQUIRED_TESTS)
    T3, T5, T8 = (sample.tests[n] for n in REQUIRED_TESTS)
    steady = {
        "T3_displacement_mm": s3.response * 1000.0, "T3_current_A": s3.current_A, "T3_gap_mm": float(T3.gap_mm),
        "T5_displacement_mm": s5.response * 1000.0, "T5_current_A": s5.current_A, "T5_voltage_V": s5.voltage_V,
        "T5_gap_mm": float(T5.gap_mm),
        "T8_force_N": s8.response, "T8_current_A": s8.current_A, "T8_gap_mm": float(T8.gap_mm),
        "kB_source": res.kB_source,
    }
    return SampleAnalytic(sid=sid, wt_pct=float(sample.wt_pct), params=res.params(), result=res, steady=steady,
                          uncertainty=res.uncertainty(), tests={"T3": T3, "T5": T5}, settling_s=settling)


_analytic = analyse_sample          # former private name (benchmarks/bench_identify.py)
_Analytic = SampleAnalytic


# ============================================================================ objectives
class _Objective:
    """The four objectives of one sample for candidates X = (log10 m, log10 zeta)."""

    def __init__(self, an: SampleAnalytic, rig, settings: IdentifySettings):
        self.sid = an.sid
        self.settings = settings
        p = an.params
        self.K2 = p.K2
        flo, fhi = settings.f_n_range_hz
        zlo, zhi = settings.zeta_range
        self.xl = np.array([math.log10(p.K2 / (2 * math.pi * fhi) ** 2), math.log10(zlo)])
        self.xu = np.array([math.log10(p.K2 / (2 * math.pi * flo) ** 2), math.log10(zhi)])
        sig_x = _noise_sigma(rig, "displacement_mm")
        self.mech = []
        self.meas = []
        for name in ("T3", "T5"):
            ts = an.tests[name]
            st = an.st[name]
            mt = population.prepare_test(ts.time_s, ts.voltage_V, MechParams.of(p, float(ts.gap_mm) / 1000.0),
                                         quiet_rtol=settings.settle_rtol)
            t = ts.time_s
            y = ts.displacement_mm
            w = metrics.smoothing_window_s(t, y, t_step=st.t_step_s, noise_sigma=sig_x, band=settings.band)
            ts_meas = metrics.settling_time_robust(t, y, t_step=st.t_step_s, noise_sigma=sig_x, band=settings.band)
            self.mech.append(mt)
            res_s = settings.ste_resolution_s
            if res_s is None:
                res_s = float(np.median(np.diff(t)))
            self.meas.append({"t": t, "y_m": y / 1000.0, "k_step": st.step, "ts_meas": ts_meas,
                              "t_step": st.t_step_s, "smooth_s": w, "window": _window_samples(t, w),
                              "resolution": float(res_s)})

    def decode(self, X) -> tuple[np.ndarray, np.ndarray]:
        """(C [N.s/m], m [kg]) from decision vectors (log10 m, log10 zeta)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        m = 10.0 ** X[:, 0]
        zeta = 10.0 ** X[:, 1]
        C = 2.0 * zeta * np.sqrt(self.K2 * m)
        return C, m

    def encode(self, C, m) -> np.ndarray:
        C = np.asarray(C, dtype=float)
        m = np.asarray(m, dtype=float)
        return np.column_stack([np.log10(m), np.log10(C / (2.0 * np.sqrt(self.K2 * m)))])

    def bounds_json(self) -> dict:
        flo, fhi = self.settings.f_n_range_hz
        zlo, zhi = self.settings.zeta_range
        return {"m_kg": [10 ** self.xl[0], 10 ** self.xu[0]], "f_n_Hz": [flo, fhi], "zeta": [zlo, zhi],
                "C_N_s_per_m_at_m": "2*zeta*sqrt(K2*m), zeta in zeta range"}

    def objectives(self, res_by_test: Sequence[BatchResult]) -> np.ndarray:
        out = []
        for meas, res in zip(self.meas, res_by_test):
            ste, rm = _objectives_one(res, meas, self.settings.band, meas["resolution"])
            out += [ste, rm]
        return np.column_stack(out)

    def evaluate(self, X) -> np.ndarray:
        return evaluate_many([self], [X])[0]


def _window_samples(t, smooth_s) -> int:
    """Odd moving-mean window in samples, as :mod:`harness.analysis.metrics` computes it (1 = none)."""
    if not smooth_s:
        return 1
    n = max(int(round(smooth_s / float(np.median(np.diff(t))))), 1)
    n = n if n % 2 == 1 else n + 1
    n = min(n, t.size if t.size % 2 == 1 else t.size - 1)
    return max(n, 1)


def _smoothed_blocks(res, t, k_step, w, groups):
    """Centered w-sample moving means of the candidates' records, in blocks.

    groups: [(idx, K)]: candidates idx need the band test only on samples [k_step, K)
    (beyond, their smoothed record is their in-band fill value). Returns
    [(idx, K, Ys)] with Ys[j] the moving mean at sample k_step + j, j = 0..K-k_step
    (time-major, one column per candidate), as metrics computes it (reflecting ends).
    """
    nt = t.size
    h = w // 2
    last_tested = nt - 1 - h
    out = []
    for idx, K in groups:
        if idx.size == 0:
            continue
        K = int(min(max(K, k_step + 2), last_tested + 1))
        lo_v, hi_v = k_step - h, K + 1 + h          # samples needed (virtual, may pass the ends)
        lo, hi = max(lo_v, 0), min(hi_v, nt)
        Y = res.dense(lo, hi, idx)
        if lo_v < 0 or hi_v > nt:
            Y = np.pad(Y, ((lo - lo_v, hi_v - hi), (0, 0)), mode="symmetric")
        if w > 1:
            P = np.empty((Y.shape[0] + 1, Y.shape[1]))
            P[0] = 0.0
            np.cumsum(Y, axis=0, out=P[1:])
            Ys = (P[w:] - P[:-w]) / w
        else:
            Ys = Y
        out.append((idx, K, Ys))
    return out


def _band_last(blocks, n, t, k_step, w, center, tol, subset=None):
    """Settling times [s]: the band test of :func:`harness.analysis.metrics.settling_time` on the blocks.

    Per candidate: the last sample k in [k_step, N-1-w//2] where |Ys_k - center| > tol;
    0 if none, NaN if it is the last tested sample or tol == 0, else the linearly
    interpolated band entry. Only candidates in ``subset`` (bool mask) are evaluated.
    """
    nt = t.size
    last_tested = nt - 1 - w // 2
    out = np.full(n, np.nan)
    for idx, K, Ys in blocks:
        if subset is not None:
            pick = subset[idx]
            if not pick.any():
                continue
            if not pick.all():
                idx, Ys = idx[pick], Ys[:, pick]
        c = center[idx]
        tl = tol[idx]
        nsearch = K - k_step
        excess = np.abs(Ys[:nsearch + 1] - c) - tl
        outside = excess[:nsearch] > 0
        any_o = outside.any(axis=0)
        j = nsearch - 1 - np.argmax(outside[::-1], axis=0)
        ok = tl > 0
        r = np.full(idx.size, np.nan)
        r[ok & ~any_o] = 0.0
        rows = np.flatnonzero(ok & any_o & (k_step + j < last_tested))
        if rows.size:
            jj = j[rows]
            ei = excess[jj, rows]
            ej = excess[jj + 1, rows]
            frac = ei / (ei - ej)
            ti, tj = t[k_step + jj], t[k_step + jj + 1]
            r[rows] = np.maximum(ti + frac * (tj - ti) - t[k_step], 0.0)
        out[idx] = r
    return out


def _sim_settling_times(res: BatchResult, t, k_step: int, band: float, w: int = 1,
                        smooth_s: float | None = None) -> np.ndarray:
    """Settling times [s] of the simulated responses, vectorized over the batch.

    Equal to ``metrics.settling_times(t, X, band, t_step=t[k_step], smooth_s=smooth_s,
    settled_final=True)`` (what :func:`harness.analysis.metrics.step_metrics` applies to a
    simulation when the noise level is known): centered moving mean of w samples, final
    level estimated on the settled part (provisional level: mean of the second half after
    the step; then the mean from t_step + Ts + smooth_s on, if that is more than the last
    10 %, else the mean of the last 10 %). NaN where a response never settles. Works on
    the compact :class:`harness.sim.results.BatchResult`: the band test only looks at the
    samples before a candidate's record turns into its in-band fill value.
    """
    nt = t.size
    h = w // 2
    n = res.n
    n_tail = max(1, int(math.ceil(0.1 * nt)))
    y0 = res.mean_before(k_step) if k_step > 0 else res.values_at(np.zeros(n, dtype=np.intp))
    L = nt - k_step
    a1 = k_step + L // 2
    yf1 = res.range_sum(a1) / (nt - a1)

    def groups(inside):
        ia, ib = np.flatnonzero(inside), np.flatnonzero(~inside)
        out = [(ib, nt)]
        if ia.size:
            # chunks of similar settling index, so that each block is only as long as needed
            ia = ia[np.argsort(res.k_fill[ia], kind="stable")]
            for ch in np.array_split(ia, min(4, ia.size)):
                out.append((np.sort(ch), int(res.k_fill[ch].max()) + h))
        return out

    def inside_for(c):
        return res.settled & (np.abs(res.x_fill - c) <= band * np.abs(c - y0))

    ins1 = inside_for(yf1)
    blocks = _smoothed_blocks(res, t, k_step, w, groups(ins1))
    ts1 = _band_last(blocks, n, t, k_step, w, yf1, band * np.abs(yf1 - y0))
    start = t[k_step] + np.where(np.isfinite(ts1), ts1, np.inf) + (smooth_s or 0.0)
    ks = np.searchsorted(t, start, side="left")
    cnt = nt - ks
    use = cnt > n_tail
    ts = np.full(n, np.nan)
    for centre_rows, centre in (("use", None), ("rest", None)):
        rows = use if centre_rows == "use" else ~use
        if not rows.any():
            continue
        if centre_rows == "use":
            c = np.full(n, np.nan)
            c[rows] = res.range_sum(np.where(rows, ks, nt))[rows] / cnt[rows]
            c = np.where(rows, c, yf1)
        else:
            c = res.tail_mean(n_tail)
        # blocks built for yf1 serve where the fill value is also in band for this level
        same = rows & (ins1 == inside_for(c))
        ts[same] = _band_last(blocks, n, t, k_step, w, c, band * np.abs(c - y0), subset=same)[same]
        other = rows & ~same
        if other.any():
            b2 = _smoothed_blocks(res, t, k_step, w, [(np.flatnonzero(other), nt)])
            ts[other] = _band_last(b2, n, t, k_step, w, c, band * np.abs(c - y0), subset=other)[other]
    return ts


def _objectives_one(res: BatchResult, meas: dict, band: float, resolution: float):
    t = meas["t"]
    sse = res.sum_sq_error(meas["y_m"])
    rmse_mm = np.sqrt(np.maximum(sse, 0.0) / t.size) * 1000.0
    tsim = _sim_settling_times(res, t, meas["k_step"], band, meas["window"], meas["smooth_s"] or None)
    t_rec = float(t[-1] - meas["t_step"])
    tsim = np.where(np.isfinite(tsim), tsim, t_rec)
    ste = np.abs(tsim - meas["ts_meas"])
    if resolution > 0:
        ste = np.round(ste / resolution) * resolution
    bad = ~np.isfinite(rmse_mm)
    rmse_mm[bad] = 1e6
    return ste, rmse_mm


_LINEAR_TAIL = True      # population.integrate's linear tail (switch for experiments)
_ELIM_DUP = False        # pymoo duplicate elimination (see _make_algorithm)


def evaluate_many(objs: Sequence[_Objective], Xs: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Objectives of several samples' candidates with one batched integration (T3 and T5 of all;
    one per sample period if the records differ in it).

    Xs[i]: decision vectors (n_i, 2) of sample i; returns the (n_i, 4) objective arrays.
    """
    jobs = []                                   # (sample index, test index, MechTest, C, m)
    for i, (o, X) in enumerate(zip(objs, Xs)):
        X = np.asarray(X, dtype=float).reshape(-1, 2)
        if X.shape[0] == 0:
            continue
        Cs, ms = o.decode(X)
        for j, mt in enumerate(o.mech):
            jobs.append((i, j, mt, Cs, ms))
    parts = {}
    steps = 0
    settle = min(o.settings.settle_rtol for o in objs) if objs else 1e-4
    rk_tol = min(o.settings.rk_tol for o in objs) if objs else 1e-3
    for dt in sorted({round(mt.dt, 12) for _, _, mt, _, _ in jobs}):
        group = [jb for jb in jobs if round(jb[2].dt, 12) == dt]
        which = np.concatenate([np.full(jb[3].size, q, dtype=np.intp) for q, jb in enumerate(group)])
        res = population.integrate([jb[2] for jb in group], which, np.concatenate([jb[3] for jb in group]),
                                   np.concatenate([jb[4] for jb in group]),
                                   PopulationSettings(settle_rtol=settle, rk_tol=rk_tol,
                                                      linear_tail=rk_tol if _LINEAR_TAIL else False))
        steps += res.candidate_steps
        pos = 0
        for i, j, _, Cs, _ in group:
            parts[(i, j)] = res.columns(pos, pos + Cs.size)
            pos += Cs.size
    out = []
    for i, o in enumerate(objs):
        if (i, 0) in parts:
            out.append(o.objectives([parts[(i, j)] for j in range(len(o.mech))]))
        else:
            out.append(np.zeros((0, 4)))
    evaluate_many.last_candidate_steps = steps
    return out


evaluate_many.last_candidate_steps = 0


# ============================================================================ Pareto / Eq. 6
def non_dominated(F) -> np.ndarray:
    """Indices of the non-dominated rows of F (minimization), duplicates kept once."""
    F = np.asarray(F, dtype=float)
    n = F.shape[0]
    keep = np.ones(n, dtype=bool)
    for i in range(n):
        if not keep[i]:
            continue
        le = np.all(F <= F[i], axis=1)
        lt = np.any(F < F[i], axis=1)
        if np.any(le & lt):
            keep[i] = False
    idx = np.flatnonzero(keep)
    # drop exact duplicates (keep the first)
    _, first = np.unique(F[idx], axis=0, return_index=True)
    return np.sort(idx[first])


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


# ============================================================================ optimization
def _make_problem(obj: _Objective):
    from pymoo.core.problem import Problem

    class CMProblem(Problem):
        """pymoo problem: 2 variables (log10 m [kg], log10 zeta [-]), 4 objectives, vectorized."""

        def __init__(self, objective: _Objective):
            super().__init__(n_var=2, n_obj=4, xl=objective.xl, xu=objective.xu)
            self.objective = objective
            self.preset_F = None      # objectives computed outside (batched over samples)

        def _evaluate(self, X, out, *args, **kwargs):
            if self.preset_F is not None:
                F, self.preset_F = self.preset_F, None
                if F.shape[0] != X.shape[0]:
                    raise RuntimeError("preset objectives do not match the population")
                out["F"] = F
            else:
                out["F"] = self.objective.evaluate(X)

    return CMProblem(obj)


def _x_of(pop) -> np.ndarray:
    """Decision vectors of a population (direct attribute access: Population.get is slow)."""
    return np.array([ind.X for ind in pop], dtype=float).reshape(len(pop), -1)


def _make_algorithm(settings: IdentifySettings):
    """pymoo's NSGA-II (SBX crossover, polynomial mutation, binary tournament, rank and
    crowding survival). Duplicate offspring are not eliminated (that cost about a fifth of
    the run time in pymoo's per-individual bookkeeping and changed neither the chosen
    models nor the size of the fronts noticeably); a duplicate is looked up in the run's
    cache of evaluated candidates instead of being simulated again."""
    from pymoo.algorithms.moo.nsga2 import NSGA2
    from pymoo.core.duplicate import DefaultDuplicateElimination
    elim = DefaultDuplicateElimination(func=_x_of) if _ELIM_DUP else False
    return NSGA2(pop_size=int(settings.pop_size), eliminate_duplicates=elim)


def _quiet_pymoo():
    try:
        from pymoo.config import Config
        Config.warnings["not_compiled"] = False
    except Exception:  # pragma: no cover
        pass


def _optimize(objs: list[_Objective], settings_list: list[IdentifySettings], on_generation=None):
    """NSGA-II for several samples in lock-step (ask/tell); their populations share one integration.

    Each sample has its own algorithm object and random generator, so its result does not
    depend on which other samples run alongside. Returns [(algorithm, problem, n_evals, time_s)].
    """
    _quiet_pymoo()
    runs = []
    for o, s in zip(objs, settings_list):
        prob = _make_problem(o)
        alg = _make_algorithm(s)
        alg.setup(prob, termination=("n_gen", int(s.n_gen)), seed=int(s.seed), verbose=False)
        runs.append({"alg": alg, "prob": prob, "obj": o, "evals": 0, "time": 0.0, "eval_time": 0.0, "cache": {}})
    while True:
        live = [r for r in runs if r["alg"].has_next()]
        if not live:
            break
        t0 = time.perf_counter()
        pops = [r["alg"].ask() for r in live]
        # candidates evaluated before (offspring equal to a parent) are not simulated again
        Xs, todo = [], []
        for r, pop in zip(live, pops):
            X = pop.get("X")
            keys = [row.tobytes() for row in X]
            new, seen = [], set()
            for i, key in enumerate(keys):
                if key not in r["cache"] and key not in seen:
                    new.append(i)
                    seen.add(key)
            Xs.append((X, keys))
            todo.append(np.asarray(new, dtype=np.intp))
        te = time.perf_counter()
        Fnew = evaluate_many([r["obj"] for r in live], [X[t] for (X, _), t in zip(Xs, todo)])
        te = time.perf_counter() - te
        n_new = sum(int(t.size) for t in todo)
        for r, t in zip(live, todo):
            r["eval_time"] += te * t.size / max(n_new, 1)
        for r, pop, (X, keys), t, F in zip(live, pops, Xs, todo, Fnew):
            for i, f in zip(t, F):
                r["cache"][keys[i]] = f
            F = np.array([r["cache"][key] for key in keys])
            r["prob"].preset_F = F
            r["alg"].evaluator.eval(r["prob"], pop)
            r["alg"].tell(infills=pop)
            r["evals"] += int(t.size)
        dt = (time.perf_counter() - t0) / len(live)
        for r in live:
            r["time"] += dt
        if on_generation is not None:
            on_generation(len(live))
    return runs


def _finish(an: SampleAnalytic, obj: _Objective, run: dict, settings: IdentifySettings, t_analytic: float
            ) -> SampleIdentification:
    alg = run["alg"]
    pop = alg.pop
    X = pop.get("X")
    F = pop.get("F")
    nd = non_dominated(F)
    X, F = X[nd], F[nd]
    C, m = obj.decode(X)
    order = np.lexsort((C, m))
    C, m, F = C[order], m[order], F[order]
    k, J = select_by_weights(F, settings.weights)
    p = an.params.with_(C=float(C[k]), m=float(m[k]))
    values = {name: (float(getattr(p, name)), PARAM_UNITS[name]) for name in PARAM_KEYS}
    chosen = {n: float(v) for n, v in zip(OBJECTIVE_NAMES, F[k])}
    chosen["J"] = float(J[k])
    return SampleIdentification(
        sample=an.sid, wt_pct=float(an.wt_pct), diameter_mm=an.params.D * 1000.0, params=p, values=values,
        uncertainty=an.uncertainty, steady=an.steady, pareto=ParetoFront(C=C, m=m, objectives=F), chosen=int(k),
        chosen_objectives=chosen, J=J, weights=settings.weights, bounds=obj.bounds_json(),
        timing_s={"analytic_s": t_analytic, "optimization_s": run["time"], "evaluation_s": run["eval_time"]},
        settings=settings,
        evaluations=int(run["evals"]))


def identify_sample(sample, dataset_rig=None, settings: IdentifySettings | None = None
                    ) -> SampleIdentification:
    """Identify one sample (tests T3, T5, T8 needed).

    sample: :class:`harness.data.dataset.Sample`; dataset_rig: the manifest's ``rig`` dict
    (or the Dataset) providing ``coil_radius_mm`` [mm] (required), ``field_per_amp_T_per_A``
    [T/A] (optional) and the sensor noise; settings: :class:`IdentifySettings`.
    Raises :class:`IdentificationError` for unusable data.
    """
    return _identify_group([sample], dataset_rig, settings or IdentifySettings())[0]


def _identify_group(samples, rig, settings: IdentifySettings, on_generation=None) -> list[SampleIdentification]:
    ans, objs, t_an = [], [], []
    for s in samples:
        ta = time.perf_counter()
        an = _analytic(s, rig, settings)
        obj = _Objective(an, rig, settings)
        ans.append(an)
        objs.append(obj)
        t_an.append(time.perf_counter() - ta)
    runs = _optimize(objs, [settings] * len(objs), on_generation=on_generation)
    out = []
    for s, an, obj, run, ta in zip(samples, ans, objs, runs, t_an):
        r = _finish(an, obj, run, settings, ta)
        r.diameter_mm = float(s.diameter_mm)
        out.append(r)
    return out


# ============================================================================ dataset
def training_samples(dataset) -> list:
    """Samples used for identification: those with T3, T5 and T8, except the paper's two unseen
    samples (15 and 25 wt%, 45 mm) kept for the generalization test."""
    from harness.data.rig import UNSEEN_SAMPLES
    unseen = {(float(w), float(d)) for w, d in UNSEEN_SAMPLES}
    return [s for s in dataset.samples
            if all(n in s.tests for n in REQUIRED_TESTS) and (float(s.wt_pct), float(s.diameter_mm)) not in unseen]


def _worker(args):
    samples, rig, settings, queue = args
    cb = (lambda n: queue.put(n)) if queue is not None else None
    c0 = time.process_time()
    res = _identify_group(samples, rig, settings, on_generation=cb)
    cpu = time.process_time() - c0
    for r in res:
        r.timing_s["process_cpu_s"] = cpu        # CPU time of the process that ran this sample's group
    return res


def identify_dataset(dataset, settings: IdentifySettings | None = None, progress: bool = True, workers: int = 2,
                     samples: Iterable[str] | None = None) -> dict:
    """Identify the training samples of a dataset; returns {sample id: SampleIdentification}.

    samples: ids to identify (default :func:`training_samples`). The samples are spread
    over ``workers`` processes; within a process their NSGA-II populations share one
    batched integration per generation. A tqdm bar counts generations x samples.
    The data of every sample are checked first: an :class:`IdentificationError` lists
    every unusable sample before any optimization starts.
    """
    settings = settings or IdentifySettings()
    if samples is None:
        chosen = training_samples(dataset)
    else:
        chosen = [dataset.sample(s) for s in samples]
    if not chosen:
        raise ValueError(f"dataset {getattr(dataset, 'root', '')} has no sample with T3, T5 and T8 to identify")
    rig = dataset.rig
    # check every sample first (fast) so that bad data fail before the optimization
    errors, cost = [], {}
    for s in chosen:
        try:
            an = _analytic(s, rig, settings)
            # relative cost of a sample: its responses settle slower -> longer integrations
            cost[s.id] = 1.0 + 10.0 * an.settling_s["T5"]
        except IdentificationError as e:
            errors.append(e)
    if len(errors) == 1:
        raise errors[0]
    if errors:
        err = IdentificationError(", ".join(e.sample for e in errors), None,
                                  "unusable data:\n  " + "\n  ".join(str(e) for e in errors))
        raise err
    workers = max(1, min(int(workers or 1), len(chosen)))
    # chunks of about equal cost (longest first to the least loaded process); the samples of a
    # chunk share one integration per generation. Results do not depend on the split.
    chunks, load = [[] for _ in range(workers)], [0.0] * workers
    for s in sorted(chosen, key=lambda s: -cost[s.id]):
        i = int(np.argmin(load))
        chunks[i].append(s)
        load[i] += cost[s.id]
    total = len(chosen) * int(settings.n_gen)
    from tqdm import tqdm
    bar = tqdm(total=total, desc="NSGA-II C, m (generations x samples)", unit="gen", disable=not progress,
               mininterval=0.5)
    results = {}
    try:
        if workers == 1:
            c0 = time.process_time()
            res = _identify_group(chosen, rig, settings, on_generation=bar.update)
            for r in res:
                r.timing_s["process_cpu_s"] = time.process_time() - c0
            results = {r.sample: r for r in res}
        else:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor
            ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else mp.get_context()
            with mp.Manager() as manager:
                queue = manager.Queue()
                with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
                    futs = [pool.submit(_worker, (c, rig, settings, queue)) for c in chunks]
                    done = 0
                    while done < total and not all(f.done() for f in futs):
                        try:
                            n = queue.get(timeout=0.2)
                        except Exception:
                            continue
                        bar.update(n)
                        done += n
                    for f in futs:
                        for r in f.result():
                            results[r.sample] = r
                    while not queue.empty():
                        bar.update(queue.get())
    finally:
        bar.close()
    return {s.id: results[s.id] for s in chosen}


# ============================================================================ JSON
def _f(x):
    x = float(x)
    return x if math.isfinite(x) else None


def sample_to_json(r: SampleIdentification) -> dict:
    """One sample's result as JSON-ready dict; every quantity's key carries its unit."""
    params = paramsjson.params_to_json(r.params, effects=False)
    unc = {PARAM_KEYS[n] + "_std": _f(v) for n, v in r.uncertainty.items()}
    front = []
    for i in range(len(r.pareto)):
        row = {PARAM_KEYS["C"]: _f(r.pareto.C[i]), PARAM_KEYS["m"]: _f(r.pareto.m[i])}
        row.update({n: _f(v) for n, v in zip(OBJECTIVE_NAMES, r.pareto.objectives[i])})
        row["J"] = _f(r.J[i])
        front.append(row)
    steady = {k: (_f(v) if not isinstance(v, str) else v) for k, v in r.steady.items()}
    return {
        "wt_pct": r.wt_pct, "diameter_mm": r.diameter_mm,
        "parameters": params,
        "parameter_std": unc,
        "steady_state": steady,
        "search_bounds": r.bounds,
        "weights": {n: w for n, w in zip(OBJECTIVE_NAMES, r.weights)},
        "chosen_index": int(r.chosen),
        "chosen_objectives": {k: _f(v) for k, v in r.chosen_objectives.items()},
        "pareto_front": front,
        "evaluations": int(r.evaluations),
        "timing": {k: _f(v) for k, v in r.timing_s.items()},
    }


def identification_to_json(results, settings: IdentifySettings | None = None, synthetic: bool | None = None,
                           wall_time_s: float | None = None) -> dict:
    """All results ({id: SampleIdentification} or a list) as one JSON-ready dict.

    Layout: {"format", "synthetic", "settings", "objectives", "samples": {id: {...,
    "parameters": {"R_Ohm", "L_H", "Em_N_m_per_T2", "K1_N_per_m3", "K2_N_per_m",
    "C_N_s_per_m", "m_kg", "a_m", "D_m", "kB_T_per_A"}, "pareto_front": [...], ...}}}.
    """
    if isinstance(results, SampleIdentification):
        results = [results]
    if not isinstance(results, dict):
        results = {r.sample: r for r in results}
    if settings is None and results:
        settings = next(iter(results.values())).settings
    out = {
        "format": "mpc-actuator-identification/1",
        "synthetic": synthetic,
        "settings": settings.to_json() if settings is not None else None,
        "objectives": {"T3_ste_s": "|2 % settling time (sim) - (meas)| of T3 [s]",
                       "T3_rmse_mm": "RMSE of the T3 displacement [mm]",
                       "T5_ste_s": "|2 % settling time (sim) - (meas)| of T5 [s]",
                       "T5_rmse_mm": "RMSE of the T5 displacement [mm]",
                       "J": "Eq. 6: sum of weight * min-max normalized objective over the front [-]"},
        "samples": {sid: sample_to_json(r) for sid, r in results.items()},
    }
    if wall_time_s is not None:
        out["wall_time_s"] = float(wall_time_s)
    return out


def write_identification(results, out_dir, settings: IdentifySettings | None = None,
                         synthetic: bool | None = None, wall_time_s: float | None = None) -> list[Path]:
    """Write ``identification.json`` and ``pareto/<sample>.csv`` (one row per front model) to out_dir."""
    import json
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    data = identification_to_json(results, settings, synthetic, wall_time_s)
    p = out_dir / "identification.json"
    p.write_text(json.dumps(data, indent=2) + "\n")
    written = [p]
    pdir = out_dir / "pareto"
    pdir.mkdir(exist_ok=True)
    for sid, s in data["samples"].items():
        cols = [PARAM_KEYS["C"], PARAM_KEYS["m"], *OBJECTIVE_NAMES, "J"]
        lines = [",".join(cols + ["chosen"])]
        for i, row in enumerate(s["pareto_front"]):
            lines.append(",".join(f"{row[c]:.10g}" if row[c] is not None else "nan" for c in cols)
                         + f",{int(i == s['chosen_index'])}")
        q = pdir / f"{sid}.csv"
        q.write_text("\n".join(lines) + "\n")
        written.append(q)
    return written


def identify_and_write(dataset, out_dir, settings: IdentifySettings | None = None, workers: int = 2,
                       progress: bool = True, samples: Iterable[str] | None = None,
                       predict_unseen: bool = True) -> tuple[dict, list[Path]]:
    """Identify a dataset's training samples and write the results (what ``mpc-actuator identify`` does).

    Writes to out_dir: ``identification.json`` (parameters per sample, with units in the
    keys, the Pareto fronts, Eq. 6 choice, settings, timing) and ``pareto/<id>.csv``; with
    predict_unseen (and at least 3 identified samples spanning a surface) also
    ``generalization.json``: surface fits of Em, K1, K2, C, m and the predicted parameters
    of the dataset's other samples (e.g. the 15 and 25 wt% ones) with the mean identified
    coil. Returns ({id: SampleIdentification}, written paths).
    """
    from harness.analysis import generalize
    settings = settings or IdentifySettings()
    t0 = time.perf_counter()
    results = identify_dataset(dataset, settings, progress=progress, workers=workers, samples=samples)
    wall = time.perf_counter() - t0
    written = write_identification(results, out_dir, settings, synthetic=getattr(dataset, "synthetic", None),
                                   wall_time_s=wall)
    if predict_unseen:
        others = [(s.id, s.wt_pct, s.diameter_mm) for s in dataset.samples if s.id not in results]
        try:
            fits = generalize.fit_surfaces(results)
        except generalize.GeneralizationError:
            fits = None
        if fits is not None:
            preds, skipped = generalize.predict_samples(fits, others, generalize.mean_coil(results))
            written.append(generalize.write_generalization(fits, preds, out_dir, skipped))
    return results, written
