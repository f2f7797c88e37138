"""The residual evaluator of the diagnosis's fits (harness.analysis.diagnosis.fitting.Evaluator): its cache is
bounded by the floats it holds, so that long (10 kHz) records cannot exhaust the memory."""
from __future__ import annotations

import pytest

from fmu_src.specs import Params
from harness.analysis.diagnosis import DiagnoseSettings
from harness.analysis.diagnosis import fitting
from harness.analysis.diagnosis.prepare import prepare
from tests.analysis.diagnosis.test_heldout import lab_dataset

P = dict(a=0.015, D=0.045, kB=0.29, R=5.0, L=0.04, Em=0.05, K1=4e5, K2=40.0, C=0.5, m=0.004)


def test_cache_hits_and_size_bound(monkeypatch):
    prep = prepare(lab_dataset(coords=((20, 45),), names=("only",)), DiagnoseSettings())
    ev = fitting.Evaluator(prep.samples, ["T1", "T5", "T8"], DiagnoseSettings())
    a, b = Params(**P), Params(**dict(P, K2=45.0))
    first = ev.parts([(0, a)])[0]
    size = sum(z.size for z in first.values())
    assert ev.n_sims == 1 and ev.cache_floats == size > 100
    again = ev.parts([(0, a), (0, a)])                   # cached: no new simulation
    assert ev.n_sims == 1 and all((again[1][k] == first[k]).all() for k in first)
    monkeypatch.setattr(fitting, "CACHE_MAX_FLOATS", int(1.5 * size))
    ev.parts([(0, b)])                                   # would exceed the bound: the cache is emptied first
    assert ev.n_sims == 2 and len(ev.cache) == 1 and ev.cache_floats == size
    ev.parts([(0, a)])                                   # evicted: simulated again
    assert ev.n_sims == 3


def test_screening_compares_the_data_chi_square_only():
    """A candidate at its reference's parameters (effect off) has lost no chi-square on the data when it is screened:
    the LM cost also holds the derived coil radius's prior residual, which the reference's data chi-square does not
    (a reference 3 prior sd off screened every candidate out by 9; deep profile, session 13: by 919). The budget is
    spent, so the screening pass stays at the start (no iteration can lower the cost)."""
    from harness.analysis.core import cpu_clock
    from harness.analysis.diagnosis.candidates import base_vector, make_params, off_init
    from harness.analysis.diagnosis.fitting import FitContext, ModelFit, ModelSpec
    st = DiagnoseSettings(workers=1)
    prep = prepare(lab_dataset(), st)
    ctx = FitContext(prep.samples, st, deadline_s=cpu_clock.now() - 1.0, coil_rel_sd=0.02)
    sh = {"ln_a_ratio": 0.06}                                    # 3 prior sd from the derivation
    base = {i: base_vector(Params(**P)) for i in range(len(prep.samples))}
    ctx.set_bounds(base)
    params = {i: make_params(s, base[i], sh) for i, s in enumerate(prep.samples)}
    ref = ModelFit(effects=(), shared=sh, base=base, params=params, fit_chi2=ctx.fit_chi2_of(params))
    cand = ctx.fit_many([ModelSpec(("sensor_lag",), base, dict(off_init(("sensor_lag",)), **sh))], reference=ref)[0]
    assert cand.screened is not None and cand.cut_short          # the case is what it claims to be
    assert abs(cand.screened.delta_chi2_shared_samples) < 1e-6, cand.screened


def test_joint_fits_leave_the_other_samples_their_share_of_the_budget():
    """The joint fits of the shared-fit samples end by their share |S|/n of the budget left, so that the samples
    fitted after them are fitted at all; no share when no other sample follows or nothing is shared."""
    from types import SimpleNamespace

    from harness.analysis.core import cpu_clock
    from harness.analysis.diagnosis.fitting import FitContext
    prep = prepare(lab_dataset(), DiagnoseSettings())
    ctx = FitContext(prep.samples, DiagnoseSettings(), deadline_s=cpu_clock.now() + 90.0)
    assert len(ctx.shared_idx) == 2 and len(prep.samples) == 3
    t0 = cpu_clock.now()
    dl = ctx.joint_deadline([SimpleNamespace(defs=[1]), SimpleNamespace(defs=[])])
    assert abs(dl - (t0 + 60.0)) < 0.5                           # 2/3 of the 90 s left
    assert ctx.joint_deadline([SimpleNamespace(defs=[])]) is None
    ctx.shared_idx = [0, 1, 2]
    assert ctx.joint_deadline([SimpleNamespace(defs=[1])]) is None


def test_discovery_lags_are_fitted_no_faster_than_a_tenth_of_the_shortest_sample_period():
    """The fits' library bounds every lag time constant (unit s) of the discovery terms from below by a tenth of the
    shortest sample period of the fit tests (deep profile, session 17: at 100 Hz a lag at the fixed 0.1 ms bound took
    a diagnosis to 166 CPU-s); never below 0.1 ms; Dahl's presliding length (unit m) keeps its range; the starts of
    a lag's fit lie inside the bounds. The periods are read here from the records' own time columns."""
    import math
    import dataclasses

    import numpy as np

    from harness.analysis.discovery.library import default_library, tau_key
    from harness.analysis.diagnosis.fitting import FitContext
    from fmu_src.terms import LAGS, TERMS
    st = DiagnoseSettings(workers=1)
    ds = lab_dataset(coords=((20, 45),), names=("only",))
    prep = prepare(ds, st)
    periods = [float(np.median(np.diff(t.time_s))) for s in ds.samples for n, t in s.tests.items()
               if n in st.fit_tests and hasattr(t, "time_s")]
    slow = [dataclasses.replace(s, tests={n: (dataclasses.replace(t, t=t.t * 500.0) if hasattr(t, "t") else
                                             dataclasses.replace(t, dt=t.dt * 500.0)) for n, t in s.tests.items()})
            for s in prep.samples]                  # the same records 500x slower (0.5 s periods: starts clipped)
    lag_terms = {n: s.lag for n, s in TERMS.items() if s.lag}
    seconds = {n: g for n, g in lag_terms.items() if getattr(LAGS[g], "constant_unit", "s") == "s"}
    assert len(seconds) >= 3 and len(seconds) < len(lag_terms)       # the case is what it claims to be
    for samples, dt in ((prep.samples, min(periods)), (slow, 500.0 * min(periods))):
        ctx = FitContext(samples, st)
        for name, lag in lag_terms.items():
            (tau,) = [d for d in ctx.defs_of((name,)) if d.key == tau_key(lag)]
            default = [d for d in default_library().params(name) if d.log][0]
            if name in seconds:
                assert math.exp(tau.lo) == pytest.approx(max(1e-4, 0.1 * dt), rel=1e-12), (name, dt)
                assert math.exp(default.lo) == pytest.approx(1e-4, rel=1e-12)
                assert tau.lo <= tau.init <= tau.hi and tau.hi == default.hi
                for start in ctx.library.starts(name, {}):
                    assert tau.lo <= start[tau.key] <= tau.hi, (name, start)
            else:
                assert (tau.lo, tau.hi) == (default.lo, default.hi), name
