"""Objectives of the C/m search of the identification: settling-time error and RMSE of simulated steps.

For candidates (C [N.s/m], m [kg]) of one sample, with R, L, Em, K1, K2 from the analytic part
(:mod:`harness.analysis.identification.analytic`), the T3 and T5 displacement steps are simulated and judged as
:func:`harness.analysis.core.metrics.step_metrics` judges a simulation when the sensor noise is known:

* RMSE [mm] over every sample of the record;
* STE [s] = |Ts_sim - Ts_meas|, 2 % settling times with the centered moving mean of
  :func:`harness.analysis.core.metrics.smoothing_window_s` applied alike to the measured and the
  simulated response and the final level estimated on the settled part
  (:func:`harness.analysis.core.metrics.settling_time_robust` for the measured record; for the
  population :func:`sim_settling_times`, a vectorized equivalent of
  ``metrics.settling_times(..., settled_final=True)`` on the compact batch result, tested equal).
  A simulation that never settles within the record gets Ts = end of record (STE stays finite and
  ordered). STE is rounded to ``ste_resolution_s`` (default: the sample period).

Order of the objectives: :data:`OBJECTIVE_NAMES` (paper Eq. 6: alpha_1..alpha_4).

Decision vectors are (log10 m, log10 zeta) with zeta = C / (2 sqrt(K2 m))
(:func:`fmu_src.diaphragm.damping_ratio`); the bounds follow from the identified K2 and the
ranges of natural frequency and damping ratio (:class:`ObjectiveSettings`).

Simulator seam: every simulation goes through :func:`_prepare_test` and :func:`_integrate`
(:mod:`harness.sim.population`: the current computed once per test from the measured voltage, a whole
population of several samples integrated at once on the vectorized simulator's compiled core, compact
results). Nothing else in the identification calls a simulator (the analytic part only uses the
exact RL step response ``harness.sim.population.zoh_current``). What the objectives need of them: a
prepared test has ``dt`` [s] (its sample period); the result of :func:`_integrate` has
``columns(a, b)`` (the candidates a..b-1 as a result of the same kind) and, per candidate,
``n``, ``settled``, ``k_fill``, ``x_fill`` (a response that stays at ``x_fill`` [m] from sample
``k_fill`` on), ``dense(lo, hi, idx)`` (samples lo..hi-1 of candidates idx, time-major, [m]),
``mean_before(k)``, ``values_at(k)``, ``range_sum(k)`` (sum from sample k to the end),
``tail_mean(n)`` and ``sum_sq_error(y_m)`` (against a measured record [m]).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from fmu_src.diaphragm import damping_coefficient, damping_ratio
from fmu_src.specs import Params
from harness.analysis.core import metrics
from harness.analysis.core.settling import smoothing_samples
from harness.data.protocol import sample_period
from harness.sim import population
from harness.sim.settings import MechParams, PopulationSettings

__all__ = ["OBJECTIVE_NAMES", "ObjectiveSettings", "StepRecord", "CMObjective", "evaluate_many",
           "sim_settling_times"]

# Order of the objectives (paper Eq. 6: alpha_1..alpha_4).
OBJECTIVE_NAMES = ("T3_ste_s", "T3_rmse_mm", "T5_ste_s", "T5_rmse_mm")


# ============================================================================ simulator seam
def _prepare_test(rec: "StepRecord", p: Params, quiet_rtol: float):
    """Everything about one test that does not depend on C and m (the simulator's test object)."""
    return population.prepare_test(rec.time_s, rec.voltage_V, MechParams.of(p, rec.gap_m), quiet_rtol=quiet_rtol,
                                   onset_delay_s=rec.onset_delay_s)


def _integrate(tests: list, which: np.ndarray, C: np.ndarray, m: np.ndarray, settings: "ObjectiveSettings"):
    """Simulate candidate k (C[k], m[k]) on tests[which[k]]; returns the compact batch result."""
    return population.integrate(tests, which, C, m, PopulationSettings(settle_rtol=settings.settle_rtol,
                                                                       rk_tol=settings.rk_tol,
                                                                       linear_tail=settings.rk_tol))


# ============================================================================ inputs
@dataclass(frozen=True)
class ObjectiveSettings:
    """f_n_range_hz [Hz], zeta_range [-]: search space (small-signal natural frequency and damping
    ratio); band: settling band (0.02 = 2 %); settle_rtol, rk_tol: tolerances of the batched
    integration; ste_resolution_s [s]: settling-time errors are rounded to it (None: the sample period)."""
    f_n_range_hz: tuple = (1.0, 100.0)
    zeta_range: tuple = (0.05, 5.0)
    band: float = 0.02
    settle_rtol: float = 1e-4
    rk_tol: float = 1e-3
    ste_resolution_s: float | None = None


@dataclass(frozen=True, eq=False)
class StepRecord:
    """A measured displacement step: time_s [s], voltage_V [V], displacement_mm [mm] arrays, gap_m [m],
    step: index of the first sample of the step; onset_delay_s [s]: for a step from rest, how long before
    that sample it began (the simulation starts it there, :func:`harness.sim.population.prepare_test`);
    None: the voltage as held over each sample interval."""
    time_s: np.ndarray
    voltage_V: np.ndarray
    displacement_mm: np.ndarray
    gap_m: float
    step: int
    onset_delay_s: float | None = None


# ============================================================================ objective
class CMObjective:
    """The four objectives of one sample for candidates X = (log10 m, log10 zeta).

    params: R, L, Em, K1, K2, a, D, kB of the sample; records: its T3 and T5 steps
    (:class:`StepRecord`); noise_sigma_mm [mm]: displacement sensor noise (None: unknown);
    settings: :class:`ObjectiveSettings`.
    """

    def __init__(self, params: Params, records: Sequence[StepRecord], noise_sigma_mm: float | None,
                 settings: ObjectiveSettings = ObjectiveSettings()):
        p = params
        self.settings = settings
        self.K2 = p.K2
        flo, fhi = settings.f_n_range_hz
        zlo, zhi = settings.zeta_range
        self.xl = np.array([math.log10(p.K2 / (2 * math.pi * fhi) ** 2), math.log10(zlo)])
        self.xu = np.array([math.log10(p.K2 / (2 * math.pi * flo) ** 2), math.log10(zhi)])
        self.mech = []
        self.meas = []
        for rec in records:
            t, y = rec.time_s, rec.displacement_mm
            t_step = float(t[rec.step])
            self.mech.append(_prepare_test(rec, p, settings.settle_rtol))
            # the band: settings.band, or the narrowest the record's noise resolves (noisy records, small steps)
            band = metrics.resolvable_band(t, y, t_step=t_step, noise_sigma=noise_sigma_mm, band=settings.band)
            w = metrics.smoothing_window_s(t, y, t_step=t_step, noise_sigma=noise_sigma_mm, band=band)
            ts_meas = metrics.settling_time_robust(t, y, t_step=t_step, noise_sigma=noise_sigma_mm, band=band)
            res_s = settings.ste_resolution_s
            if res_s is None:
                res_s = sample_period(t)
            self.meas.append({"t": t, "y_m": y / 1000.0, "k_step": rec.step, "ts_meas": ts_meas,
                              "t_step": t_step, "smooth_s": w, "window": smoothing_samples(t, w), "band": band,
                              "resolution": float(res_s)})

    def decode(self, X) -> tuple[np.ndarray, np.ndarray]:
        """(C [N.s/m], m [kg]) from decision vectors (log10 m, log10 zeta)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        m = 10.0 ** X[:, 0]
        return damping_coefficient(10.0 ** X[:, 1], self.K2, m), m

    def encode(self, C, m) -> np.ndarray:
        """Decision vectors (log10 m, log10 zeta) of (C [N.s/m], m [kg])."""
        C = np.asarray(C, dtype=float)
        m = np.asarray(m, dtype=float)
        return np.column_stack([np.log10(m), np.log10(damping_ratio(C, self.K2, m))])

    def bounds_json(self) -> dict:
        """The search space with units in the keys."""
        flo, fhi = self.settings.f_n_range_hz
        zlo, zhi = self.settings.zeta_range
        return {"m_kg": [10 ** self.xl[0], 10 ** self.xu[0]], "f_n_Hz": [flo, fhi], "zeta": [zlo, zhi],
                "C_N_s_per_m_at_m": "2*zeta*sqrt(K2*m), zeta in zeta range"}

    def objectives(self, res_by_test: Sequence) -> np.ndarray:
        """(n, 4) objectives from the batch results of T3 and T5 (same candidates)."""
        out = []
        for meas, res in zip(self.meas, res_by_test):
            ste, rm = _objectives_one(res, meas, meas["band"], meas["resolution"])
            out += [ste, rm]
        return np.column_stack(out)

    def evaluate(self, X) -> np.ndarray:
        """(n, 4) objectives of decision vectors X (n, 2)."""
        return evaluate_many([self], [X])[0]


def evaluate_many(objs: Sequence[CMObjective], Xs: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Objectives of several samples' candidates with one batched integration (T3 and T5 of all;
    one per sample period if the records differ in it).

    Xs[i]: decision vectors (n_i, 2) of sample i; returns the (n_i, 4) objective arrays.
    """
    jobs = []                                   # (sample index, test index, prepared test, C, m)
    for i, (o, X) in enumerate(zip(objs, Xs)):
        X = np.asarray(X, dtype=float).reshape(-1, 2)
        if X.shape[0] == 0:
            continue
        Cs, ms = o.decode(X)
        for j, mt in enumerate(o.mech):
            jobs.append((i, j, mt, Cs, ms))
    settings = ObjectiveSettings(settle_rtol=min(o.settings.settle_rtol for o in objs) if objs else 1e-4,
                                 rk_tol=min(o.settings.rk_tol for o in objs) if objs else 1e-3)
    parts = {}
    for dt in sorted({round(mt.dt, 12) for _, _, mt, _, _ in jobs}):
        group = [jb for jb in jobs if round(jb[2].dt, 12) == dt]
        which = np.concatenate([np.full(jb[3].size, q, dtype=np.intp) for q, jb in enumerate(group)])
        res = _integrate([jb[2] for jb in group], which, np.concatenate([jb[3] for jb in group]),
                         np.concatenate([jb[4] for jb in group]), settings)
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
    return out


# ============================================================================ settling times
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
    """Settling times [s]: the band test of :func:`harness.analysis.core.metrics.settling_time` on the blocks.

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


def sim_settling_times(res, t, k_step: int, band: float, w: int = 1,
                        smooth_s: float | None = None) -> np.ndarray:
    """Settling times [s] of the simulated responses, vectorized over the batch.

    Equal to ``metrics.settling_times(t, X, band, t_step=t[k_step], smooth_s=smooth_s,
    settled_final=True)`` (what :func:`harness.analysis.core.metrics.step_metrics` applies to a
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
    for settled_part in (True, False):
        # final level: mean from t_step + Ts1 + smooth_s on where that is more than the last 10 %, else tail mean
        rows = use if settled_part else ~use
        if not rows.any():
            continue
        if settled_part:
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


def _objectives_one(res, meas: dict, band: float, resolution: float):
    t = meas["t"]
    sse = res.sum_sq_error(meas["y_m"])
    rmse_mm = np.sqrt(np.maximum(sse, 0.0) / t.size) * 1000.0
    tsim = sim_settling_times(res, t, meas["k_step"], band, meas["window"], meas["smooth_s"] or None)
    t_rec = float(t[-1] - meas["t_step"])
    tsim = np.where(np.isfinite(tsim), tsim, t_rec)
    ste = np.abs(tsim - meas["ts_meas"])
    if resolution > 0:
        ste = np.round(ste / resolution) * resolution
    bad = ~np.isfinite(rmse_mm)
    rmse_mm[bad] = 1e6
    return ste, rmse_mm
