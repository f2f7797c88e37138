"""The identification's prepared data (harness.analysis.identification.prepared): derived once, then only read.

Counted, not assumed: the conventions are inferred once per identification, every step instant is fitted
once (``analytic.step_instant`` wrapped with a counter), and the objectives and the least-squares estimate
never fit one again. Frozen: no attribute of the prepared data or of the conventions can be rebound, and
their mappings refuse changes; it survives pickling (it reaches the worker processes).
"""
import dataclasses
import functools
import pickle

import numpy as np
import pytest

from harness.analysis.identification import analytic, conventions, identify, prepared
from harness.data import rig
from harness.data.dataset import Dataset, Sample
from harness.sim import virtual_rig

TINY = identify.IdentifySettings(pop_size=8, n_gen=2)


@functools.lru_cache(maxsize=None)
def _sample(w, d):
    sid, _, tests = virtual_rig.generate_sample(w, d, seed=0, simulator=virtual_rig.ModelSimulator())
    return Sample(id=sid, wt_pct=float(w), diameter_mm=float(d), thickness_mm=rig.THICKNESS_MM, tests=tests)


def _dataset():
    return Dataset(root=None, synthetic=False, description="test", rig=rig.rig_description(),
                   samples=[_sample(10, 30), _sample(20, 45)])


@pytest.fixture
def counted(monkeypatch):
    """Counters of the conventions' inference and of the step-instant fits (keyed by test and record)."""
    calls = {"infer": 0, "fits": []}
    real_infer, real_fit = prepared.infer_conventions, analytic.step_instant

    def infer(*a, **k):
        calls["infer"] += 1
        return real_infer(*a, **k)

    def fit(test, *a, **k):
        calls["fits"].append((test.name, float(test.time_s[0]), float(np.sum(test.current_A))))
        return real_fit(test, *a, **k)

    monkeypatch.setattr(prepared, "infer_conventions", infer)
    monkeypatch.setattr(analytic, "step_instant", fit)
    return calls


def _pure_steps(ds) -> int:
    """Time series of the dataset that are a step from rest (0 V, then a constant voltage), counted here."""
    n = 0
    for s in ds.samples:
        for ts in s.tests.values():
            V = getattr(ts, "voltage_V", None)
            if V is None or not np.any(V > 0):
                continue
            on = np.flatnonzero(V > 0)[0]
            n += bool(np.all(V[:on] == 0) and np.allclose(V[on:], V[on]))
    return n


def test_identification_derives_the_prepared_data_once(tmp_path, counted):
    ds = _dataset()
    identify.identify_and_write(ds, tmp_path, TINY, workers=1, progress=False, predict_unseen=False)
    assert counted["infer"] == 1
    fits = counted["fits"]
    assert len(fits) == len(set(fits)), "a step instant was fitted twice"
    assert len(fits) == _pure_steps(ds) > 0


def test_objectives_read_the_instants_of_the_analytic_step(counted):
    """From a bare manifest rig (``identify_sample``'s public form) T3 and T5 are fitted once, in
    ``analyse_sample``; the objectives (as the least-squares estimate builds them, many times) fit none."""
    s = _sample(20, 45)
    an = identify.analyse_sample(s, rig.rig_description(), TINY)
    assert sorted(name for name, _, _ in counted["fits"]) == ["T3", "T5"]
    before = len(counted["fits"])
    for scale in (1.0, 1.1, 0.9):
        p = an.params.with_(L=an.params.L * scale)
        identify.objective_for(dataclasses.replace(an, params=p), rig.rig_description(), TINY, coil_step=True)
    assert len(counted["fits"]) == before


def test_the_prepared_data_are_frozen():
    ds = _dataset()
    p = prepared.prepare(ds)
    for name, value in (("coil_radius_mm", 1.0), ("noise_sigma", {}), ("steps", None), ("conventions", None)):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(p, name, value)
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.conventions.noise_floor = {}
    with pytest.raises(TypeError):
        p.noise_sigma["displacement_mm"] = 0.0
    with pytest.raises(TypeError):
        p.steps[ds.samples[0].id]["T5"] = None
    with pytest.raises(TypeError):
        p.steps.pop(ds.samples[0].id)
    q = pickle.loads(pickle.dumps(p))
    assert q == p and isinstance(q.steps, prepared.ReadOnlyDict)
    with pytest.raises(TypeError):
        q.noise_sigma.update(force_N=1.0)


def test_the_prepared_data_read_the_conventions():
    """What the identification reads equals what the conventions state (manifest, else the data)."""
    ds = _dataset()
    conv = conventions.infer_conventions(ds)
    p = prepared.prepare(ds, conv)
    assert p.conventions is conv
    assert p.coil_radius_mm == ds.rig["coil_radius_mm"] == conv.coil_radius_mm
    for col in conventions.NOISE_COLUMNS:
        assert p.noise_sigma[col] == ds.rig["sensors"][col]["noise_sigma"]
    for s in ds.samples:
        assert dict(p.step_instants(s.id)) == conv.steps[s.id]
    bare = prepared.PreparedData.from_rig(ds.rig)
    assert bare.steps is None and bare.step_instants("W20-D45") is None
    assert dict(bare.noise_sigma) == dict(p.noise_sigma)
