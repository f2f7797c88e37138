"""Monte-Carlo prediction bands: parameter draws (:mod:`harness.analysis.identification.parameter_uncertainty`) run through the
vectorized simulator (:func:`harness.sim.simulator.simulate`) on every test of a sample, and the draws of
unseen samples through the generalization surfaces (one surface fit per draw).

For a test, every draw is one run of the paper's model (effects off) with the test's input: the
measured voltage, held over each sample interval, for the time series (T2-T6, T8); a constant
voltage (nominal field / kB x R) held ``hold_s`` at each gap for the sweeps (T1, T7), the reading
averaged over the last ``average_s`` as on the rig. The band is the 2.5/50/97.5 % percentiles of the
draws at each time or gap (the model's uncertainty); ``inside_pct`` is the share of the measured
points inside that band widened by the sensor's noise floor (+-1.96 sigma: a 95 % prediction band of
a measurement, the noise taken as independent of the parameters).

Units: readings in the dataset's units (displacement_mm [mm], force_N [N]); times [s], gaps [mm].
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fmu_src.specs import Params
from harness.analysis.identification import generalize
from harness.analysis.identification.parameter_uncertainty import PARAMS
from harness.data import protocol
from harness.sim.settings import Schedule
from harness.sim.simulator import PARAM_FIELDS, Runs, simulate

__all__ = ["Band", "runs_of", "test_band", "sample_bands", "unseen_draws", "PERCENTILES"]

PERCENTILES = (2.5, 50.0, 97.5)
_EFFECT_FIELDS = tuple(f for f in PARAM_FIELDS if f not in ("a", "r0", "D", "kB", *PARAMS))


@dataclass(frozen=True)
class Band:
    """Prediction band of one test of one sample.

    test, column (measured column, e.g. "displacement_mm"); axis_name ("time_s" or "gap_mm"), axis;
    lo, med, hi: percentiles of the simulated reading over the draws; measured: the data (or None);
    noise: sensor noise floor (column unit); inside_pct: measured points inside [lo, hi] +- 1.96 noise [%].
    """
    test: str
    column: str
    axis_name: str
    axis: np.ndarray
    lo: np.ndarray
    med: np.ndarray
    hi: np.ndarray
    measured: np.ndarray | None
    noise: float
    inside_pct: float

    def steady(self) -> dict:
        """Band of the steady value (time series: mean over the last half of the record; sweep: the largest
        median): {"lo", "med", "hi", "measured"} in the column's unit."""
        if self.axis_name == "time_s":
            sl = slice(self.axis.size // 2, None)
            pick = {k: float(np.mean(v[sl])) if v is not None else float("nan")
                    for k, v in (("lo", self.lo), ("med", self.med), ("hi", self.hi), ("measured", self.measured))}
            return pick
        k = int(np.argmax(self.med))
        return {"lo": float(self.lo[k]), "med": float(self.med[k]), "hi": float(self.hi[k]),
                "measured": float(self.measured[k]) if self.measured is not None else float("nan")}


def runs_of(base: Params, rows: np.ndarray, gap_m, blocked: bool, V, dt: float) -> Runs:
    """Runs of the draws ``rows`` ((n, 7), order PARAMS) at gap(s) ``gap_m`` [m] with input V (see Runs)."""
    rows = np.atleast_2d(rows)
    n = rows.shape[0]
    par = {k: np.full(n, float(getattr(base, k))) for k in ("a", "D", "kB")}
    par.update({k: rows[:, i].astype(float) for i, k in enumerate(PARAMS)})
    par["r0"] = np.broadcast_to(np.asarray(gap_m, dtype=float), (n,)).copy()
    par.update({k: np.zeros(n) for k in _EFFECT_FIELDS})
    return Runs(params=par, blocked=np.full(n, bool(blocked)), V=np.asarray(V, dtype=float), dt=dt)


def _percentiles(y: np.ndarray):
    lo, med, hi = np.percentile(y, PERCENTILES, axis=0)
    return lo, med, hi


def _inside(measured, lo, hi, noise: float) -> float:
    if measured is None:
        return float("nan")
    w = 1.959963984540054 * noise
    ok = (measured >= lo - w) & (measured <= hi + w)
    return 100.0 * float(np.mean(ok))


def test_band(test, base: Params, rows: np.ndarray, rig) -> Band:
    """The band of one test (a dataset TimeSeries or GapSweep) for the draws ``rows`` (module docstring)."""
    d = protocol.TESTS[test.test]
    col = d.measured
    scale = 1000.0 if col == "displacement_mm" else 1.0
    noise = protocol.noise_floor(rig, col) or 0.0
    meas = getattr(test, col, None)
    if hasattr(test, "time_s"):
        t = np.asarray(test.time_s, dtype=float)
        dt = protocol.sample_period(t)
        V = np.asarray(test.voltage_V, dtype=float)[:-1]
        n = rows.shape[0]
        res = simulate(runs_of(base, rows, float(test.gap_mm) / 1000.0, d.blocked, np.tile(V, (n, 1)), dt))
        y = res.y[:, :t.size] * scale
        lo, med, hi = _percentiles(y)
        return Band(test.test, col, "time_s", t, lo, med, hi, meas, noise, _inside(meas, lo, hi, noise))
    timing = protocol.sweep_timing(rig)
    gaps = np.asarray(test.gap_mm, dtype=float)
    V = float(test.field_T) / base.kB * base.R
    n, k = rows.shape[0], gaps.size
    rr = np.repeat(rows, k, axis=0)
    gg = np.tile(gaps / 1000.0, n)
    res = simulate(runs_of(base, rr, gg, d.blocked, np.full(n * k, V), timing.sample_period_s),
                   Schedule(t_end=timing.hold_s, fine_s=min(0.5, timing.hold_s)))
    mask = protocol.sweep_average_mask(res.t, timing.average_s)
    y = (res.y[:, mask].mean(axis=1) * scale).reshape(n, k)
    lo, med, hi = _percentiles(y)
    return Band(test.test, col, "gap_mm", gaps, lo, med, hi, meas, noise, _inside(meas, lo, hi, noise))


def sample_bands(sample, base: Params, rows: np.ndarray, rig, tests=None) -> dict:
    """{test: Band} for the tests of a dataset sample (all of them unless ``tests`` names some)."""
    names = [n for n in sample.tests if tests is None or n in tests]
    return {n: test_band(sample.tests[n], base, rows, rig) for n in names}


def unseen_draws(training: dict, targets, n: int, rngs: dict) -> dict:
    """Draws of unseen samples through the surfaces: one surface fit per draw of every training sample.

    training: {id: ParameterUncertainty}; targets: [(id, wt_pct, diameter_mm)]; rngs: {training id:
    numpy Generator} (one per sample: the draws do not depend on the order or the grouping of work).
    Returns {target id: (base Params, (n, 7) draws)}; coil (R, L) of a draw: the mean over the samples.
    Raises :class:`harness.analysis.identification.generalize.GeneralizationError` for a target outside the hull.
    """
    ids = list(training)
    rows = {sid: training[sid].draws(n, rngs[sid]) for sid in ids}
    out = {tid: np.empty((n, len(PARAMS))) for tid, _, _ in targets}
    iR, iL = PARAMS.index("R"), PARAMS.index("L")
    for j in range(n):
        ent = [(training[s].wt_pct, training[s].diameter_mm, dict(zip(PARAMS, rows[s][j]))) for s in ids]
        fits = generalize.fit_surfaces(ent)
        R = float(np.mean([rows[s][j, iR] for s in ids]))
        L = float(np.mean([rows[s][j, iL] for s in ids]))
        for tid, w, dmm in targets:
            pred = generalize.predict(fits, w, dmm)
            out[tid][j] = [R, L] + [pred[k] for k in PARAMS[2:]]
    first = training[ids[0]].params
    res = {}
    for tid, w, dmm in targets:
        med = np.median(out[tid], axis=0)
        base = first.with_(D=float(dmm) / 1000.0, **{k: float(v) for k, v in zip(PARAMS, med)})
        res[tid] = (base, out[tid])
    return res


def band_summary_row(sid: str, band: Band) -> dict:
    """A table row: the steady value's band and the share of measured points inside the prediction band
    (displacements in the *_mm columns, forces in the *_N columns; the other unit's columns are None)."""
    s = band.steady()
    unit = "mm" if band.column == "displacement_mm" else "N"
    row = {"sample": sid, "test": band.test,
           "quantity": ("max over gaps " if band.axis_name == "gap_mm" else "steady ") + band.column}
    for u in ("mm", "N"):
        for key, name in (("lo", "p2.5"), ("med", "p50"), ("hi", "p97.5"), ("measured", "measured")):
            row[f"{name}_{u}"] = s[key] if u == unit else None
    row["inside_band_pct"] = band.inside_pct if math.isfinite(band.inside_pct) else None
    return row
