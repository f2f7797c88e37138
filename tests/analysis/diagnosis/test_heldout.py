"""Held-out samples of the diagnosis (harness.analysis.diagnosis.heldout): the user's choice, then one rule that
does not depend on the virtual rig's sample names."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from harness.analysis.diagnosis import DiagnoseSettings, UnseenSampleError, declared_unseen
from harness.analysis.diagnosis.fitting import FitContext
from harness.analysis.diagnosis.heldout import shared_fit_samples
from harness.analysis.diagnosis.prepare import prepare
from harness.data.dataset import Dataset, GapSweep, Sample, TimeSeries

RIG = {"coil_radius_mm": 15.0, "field_per_amp_T_per_A": 0.29, "sample_period_s": 1e-3,
       "sweep_hold_s": 1.5, "sweep_average_s": 0.3,
       "sensors": {"displacement_mm": {"noise_floor": 0.005}, "force_N": {"noise_floor": 5e-4},
                   "current_A": {"noise_floor": 2e-3}}}


def _tests() -> dict:
    t = np.arange(3001) * 1e-3
    V = np.where(t >= 0.2 - 1e-12, 4.0, 0.0)
    I = np.where(V > 0, 0.8, 0.0)
    x = np.where(V > 0, 0.1, 0.0)
    return {"T5": TimeSeries("T5", None, t, V, I, x, None, 0.23, 5.0),
            "T8": TimeSeries("T8", None, t, V, I, None, 0.5 * I, 0.23, 2.0),
            "T1": GapSweep("T1", None, np.arange(5.0, -1.0, -1.0), np.full(6, 0.8), np.linspace(0.01, 0.5, 6), None,
                           0.23)}


def lab_dataset(coords=((15, 45), (25, 45), (20, 45)), names=("alpha", "beta", "gamma"), synthetic=False):
    """Another lab's dataset: its own sample names; two samples at the virtual rig's unseen fractions."""
    return Dataset(None, synthetic, "another rig", RIG,
                   [Sample(n, float(w), float(d), 1.5, _tests()) for n, (w, d) in zip(names, coords)])


def fake(coords, unseen=()):
    return [SimpleNamespace(sid=f"S{k}", wt_pct=w, diameter_mm=d, unseen=f"S{k}" in unseen)
            for k, (w, d) in enumerate(coords)]


@pytest.mark.parametrize("synthetic", [False, True])
def test_nothing_declared_nothing_unseen_whatever_the_fractions(synthetic):
    # the virtual rig's unseen fractions (15, 25 wt% at 45 mm) are ordinary samples unless declared
    prep = prepare(lab_dataset(synthetic=synthetic), DiagnoseSettings())
    assert [s.unseen for s in prep.samples] == [False, False, False]
    ctx = FitContext(prep.samples, DiagnoseSettings())
    # (diameter, fraction) order alpha 15, gamma 20, beta 25: the two ends fit, the middle one is held out
    assert [prep.samples[i].sid for i in ctx.shared_idx] == ["alpha", "beta"]


def test_declared_samples_are_held_out():
    st = DiagnoseSettings(unseen=("alpha",))
    prep = prepare(lab_dataset(), st)
    assert [s.unseen for s in prep.samples] == [True, False, False]
    ctx = FitContext(prep.samples, st)
    assert [prep.samples[i].sid for i in ctx.shared_idx] == ["beta", "gamma"]


def test_unknown_or_all_declared_is_an_error_naming_them():
    with pytest.raises(UnseenSampleError, match=r"W15-D45 declared unseen .* not in the dataset .*alpha, beta, gamma"):
        prepare(lab_dataset(), DiagnoseSettings(unseen=("alpha", "W15-D45")))
    with pytest.raises(UnseenSampleError, match="every sample .* declared unseen"):
        declared_unseen(["a", "b"], ["b", "a"])
    assert declared_unseen(["a", "b", "c"], ["c", "a"]) == ("a", "c")        # dataset order
    assert declared_unseen(["a"], None) == () and declared_unseen(["a"], []) == ()
    assert DiagnoseSettings(unseen="alpha").unseen == ("alpha",)


def test_rule_spreads_over_geometry_and_keeps_one_out():
    st = DiagnoseSettings()
    grid = [(w, d) for d in (30, 45, 60) for w in (10, 20, 30)] + [(15, 45), (25, 45)]
    s = fake(grid)
    # 11 samples sorted by (diameter, fraction): picks 0, 3, 7, 10 -> W10-D30, W10-D45, W30-D45, W30-D60
    assert [grid[i] for i in shared_fit_samples(s, st)] == [(10, 30), (10, 45), (30, 45), (30, 60)]
    assert shared_fit_samples(fake([(20, 45), (30, 60)]), st) == [0, 1]              # 2 < min_samples_holdout
    assert len(shared_fit_samples(fake([(10, 30), (20, 45), (30, 60)]), st)) == 2   # one held out
    # declared: held out whatever the rule would have picked; the rest all fit when few enough
    got = shared_fit_samples(fake([(10, 30), (20, 45), (30, 60)], unseen=("S0",)), st)
    assert got == [1, 2]
    with pytest.raises(UnseenSampleError):
        shared_fit_samples(fake([(10, 30)], unseen=("S0",)), st)
