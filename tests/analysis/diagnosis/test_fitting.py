"""The residual evaluator of the diagnosis's fits (harness.analysis.diagnosis.fitting.Evaluator): its cache is
bounded by the floats it holds, so that long (10 kHz) records cannot exhaust the memory."""
from __future__ import annotations

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
