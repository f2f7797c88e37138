"""Monte-Carlo prediction bands (harness.analysis.uncertainty.bands): with no parameter spread the band collapses onto the
model's response, which must equal the compiled integrator's (fmu_src.model.simulate, another solver); with
spread the percentiles are ordered and widen; unseen samples' draws go through the surfaces."""
import numpy as np
import pytest

from fmu_src.model import simulate as model_simulate
from harness.analysis.uncertainty import bands
from harness.analysis.identification import generalize
from harness.analysis.identification import parameter_uncertainty as U
from harness.data import protocol, rig
from harness.data.records import GapSweep, TimeSeries

P = rig.true_params(20, 45)
RIG = rig.rig_description()


def _t5(gap_mm=9.0):
    t = protocol.time_grid(0.2 + 0.8)
    V = protocol.step_voltage(t, 0.23 / P.kB * P.R)
    r = model_simulate(P.with_(r0=gap_mm / 1e3), t, V)
    return TimeSeries(test="T5", file=None, time_s=t, voltage_V=V, current_A=r["I"], field_T=0.23, gap_mm=gap_mm,
                      frequency_hz=None, displacement_mm=r["x"] * 1e3, force_N=None), r


def _rows(n, rel_sd, seed=0):
    mean = np.array([getattr(P, k) for k in U.PARAMS])
    u = U.ParameterUncertainty("W20-D45", 20.0, 45.0, P, np.diag((rel_sd * mean) ** 2))
    return u.draws(n, np.random.default_rng(seed)) if rel_sd > 0 else np.tile(mean, (n, 1))


def test_band_without_spread_is_the_compiled_integrators_response():
    ts, r = _t5()
    b = bands.test_band(ts, P, _rows(4, 0.0), RIG)
    np.testing.assert_array_equal(b.lo, b.hi)
    scale = np.max(np.abs(r["x"])) * 1e3
    assert np.max(np.abs(b.med - r["x"] * 1e3)) <= 2e-4 * scale
    assert b.inside_pct == 100.0


def test_band_with_spread_is_ordered_and_covers_the_truth():
    ts, _ = _t5()
    b = bands.test_band(ts, P, _rows(24, 0.05), RIG)
    assert np.all(b.lo <= b.med + 1e-15) and np.all(b.med <= b.hi + 1e-15)
    late = slice(b.axis.size // 2, None)
    assert np.all(b.hi[late] - b.lo[late] > 0.02 * np.max(b.med))      # 5 % parameter spread shows
    assert b.inside_pct > 95.0                                          # the truth lies inside
    row = bands.band_summary_row("W20-D45", b)
    assert row["p2.5_mm"] < row["p50_mm"] < row["p97.5_mm"] and row["p50_N"] is None


def test_sweep_band_equals_steady_runs_at_each_gap():
    gaps = np.array([12.0, 6.0])
    V = 0.06 / P.kB * P.R
    sw = GapSweep(test="T1", file=None, gap_mm=gaps, current_A=np.full(2, V / P.R), field_T=0.06,
                  displacement_mm=np.zeros(2), force_N=None)
    b = bands.test_band(sw, P, _rows(2, 0.0), RIG)
    t = protocol.time_grid(protocol.SWEEP_HOLD_S)
    for k, g in enumerate(gaps):
        r = model_simulate(P.with_(r0=g / 1e3), t, np.full(t.size, V))
        ref = np.mean(r["x"][protocol.sweep_average_mask(t, protocol.SWEEP_AVERAGE_S)]) * 1e3
        assert b.med[k] == pytest.approx(ref, rel=1e-4)


def test_unseen_draws_without_spread_are_the_surface_prediction():
    tr = {}
    for w, d in rig.TRAINING_SAMPLES:
        p = rig.true_params(w, d)
        tr[rig.sample_id(w, d)] = U.ParameterUncertainty(rig.sample_id(w, d), float(w), float(d), p, np.zeros((7, 7)))
    rngs = {k: np.random.default_rng(1) for k in tr}
    out = bands.unseen_draws(tr, [("W15-D45", 15.0, 45.0)], 3, rngs)
    base, rows = out["W15-D45"]
    fits = generalize.fit_surfaces([(u.wt_pct, u.diameter_mm, u.params) for u in tr.values()])
    pred = generalize.predict(fits, 15.0, 45.0)
    for k in ("Em", "K1", "K2", "C", "m"):
        np.testing.assert_allclose(rows[:, U.PARAMS.index(k)], pred[k], rtol=1e-12)
        assert getattr(base, k) == pytest.approx(pred[k], rel=1e-12)
    assert base.D == pytest.approx(0.045)
    with pytest.raises(generalize.GeneralizationError, match="convex hull"):
        bands.unseen_draws(tr, [("W5-D45", 5.0, 45.0)], 1, rngs)
