"""The residual layout of the diagnosis's fits is fixed by the data (issue "Any valid dataset").

A residual lives on the measured grid, in windows chosen from the data alone: its length must not depend on
the parameters, nor on which other simulations share a batch (the lock-step Levenberg-Marquardt drops problems
as they converge, so the batch changes between iterations). The defect this guards against ended the diagnosis
of a 500 Hz dataset of another rig with ``operands could not be broadcast together with shapes (2608,)
(2596,)``: the simulator's coarse output grid, and so the number of step-test residuals, followed the longest
record of the batch. ``tests/fixtures/clean-500hz-3-samples`` is a reduced copy of that bug report's dataset
(3 of its 11 samples, files unchanged); the old code failed on it in 2 s.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness.analysis.diagnosis import DiagnoseSettings
from harness.analysis.diagnosis.candidates import base_vector, make_params
from harness.analysis.diagnosis.fitting import Evaluator
from harness.analysis.diagnosis.prepare import Series, Sweep, prepare
from harness.analysis.core.lsq import BoxProblem, LMSettings, ResidualLayoutError, levenberg_marquardt
from harness.data.dataset import read_dataset

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "clean-500hz-3-samples"
NAMES = ["T1", "T3", "T5", "T8"]
COARSE_OUT = 4          # the simulator's default Schedule.coarse_out


@pytest.fixture(scope="module")
def prepared():
    st_ = DiagnoseSettings()
    return prepare(read_dataset(FIXTURE), st_), st_


def expected_length(test, fine_s: float) -> int:
    """The number of residuals of one channel of a test, counted by hand from the record: a step test is
    compared at every sample for fine_s after its first 'on' sample, then at every 4th, the first sample left
    out when it is the step instant itself (nothing has moved yet); a sweep at every gap of its fit mask."""
    if isinstance(test, Sweep):
        return int(np.count_nonzero(test.fit_mask)) if test.fit_mask is not None else test.gaps.size
    n_loc = test.t.size - test.k_on
    if test.V_on is None:
        return test.t.size
    n_fine = min(n_loc - 1, round(fine_s / test.dt))
    n = n_fine + 1 + (n_loc - 1 - n_fine) // COARSE_OUT
    return n - (0 if test.step_delay_s > 0 else 1)


def _params(sd, scale_C, scale_m, scale_K2):
    p = make_params(sd, np.log([5.0, 0.04, 0.05, 4e5, 40.0, 0.5, 0.004]), {})
    return p.with_(C=p.C * scale_C, m=p.m * scale_m, K2=p.K2 * scale_K2)


def test_the_fixture_is_the_bug_reports_kind_of_data(prepared):
    prep, _ = prepared
    assert [s.sid for s in prep.samples] == ["W10-D30", "W20-D45", "W30-D60"]
    for s in prep.samples:
        for name in ("T3", "T5", "T8"):
            t = s.tests[name]
            assert isinstance(t, Series) and t.dt == pytest.approx(2e-3)
    # records of different lengths: the batch's longest record is not every test's
    lengths = {s.tests[n].t.size - s.tests[n].k_on for s in prep.samples for n in ("T3", "T5", "T8")}
    assert len(lengths) > 1


@settings(max_examples=12, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(scales=st.lists(st.tuples(st.floats(0.2, 5.0), st.floats(0.3, 3.0), st.floats(0.7, 1.4)),
                       min_size=1, max_size=4),
       subset=st.lists(st.integers(0, 2), min_size=1, max_size=5))
def test_residual_lengths_depend_on_the_data_alone(prepared, scales, subset):
    """Whatever the parameters and whatever shares the batch, each (sample, test, channel) has the hand-counted
    number of residuals, and a job's residuals do not depend on the other jobs of its batch."""
    prep, st_ = prepared
    ev = Evaluator(prep.samples, NAMES, st_)
    jobs = [(i, _params(prep.samples[i], *scales[k % len(scales)])) for k, i in enumerate(subset)]
    parts = ev.parts(jobs)
    for (i, _), pp in zip(jobs, parts):
        sd = prep.samples[i]
        for (name, ch), z in pp.items():
            assert z.size == expected_length(sd.tests[name], st_.fine_s), (sd.sid, name, ch)
    # each job alone (a fresh evaluator: no cache), in a batch of one
    for (i, p), pp in zip(jobs, parts):
        alone = Evaluator(prep.samples, NAMES, st_).parts([(i, p)])[0]
        for k in pp:
            assert alone[k].size == pp[k].size
            np.testing.assert_allclose(alone[k], pp[k], rtol=1e-9, atol=1e-9)


def test_the_lsq_layer_names_the_problem_whose_residual_changes_length():
    calls = {"n": 0}

    def residuals(points):
        out = []
        for _, x in points:
            calls["n"] += 1
            n = 10 if calls["n"] <= 3 else 11         # a defect: the length changes after the first batch
            out.append(np.full(n, x[0] - 1.0))
        return out

    prob = BoxProblem(np.array([3.0]), np.array([-10.0]), np.array([10.0]), np.array([1e-6]),
                      label="sample S1, C and m")
    with pytest.raises(ResidualLayoutError, match=r"sample S1, C and m.* 11 entries .* first had 10"):
        levenberg_marquardt([prob, prob], residuals, LMSettings(max_iter=5))


def test_the_evaluator_names_sample_test_and_signal_when_the_layout_breaks(prepared, monkeypatch):
    prep, st_ = prepared
    ev = Evaluator(prep.samples, NAMES, st_)
    p = _params(prep.samples[1], 1.0, 1.0, 1.0)
    ev.parts([(1, p)])
    from harness.analysis.diagnosis import fitting
    real = fitting.residual_parts

    def broken(sd, sims, names, robust_c=None):
        out = real(sd, sims, names, robust_c)
        out[("T5", "y")] = out[("T5", "y")][:-3]
        return out

    monkeypatch.setattr(fitting, "residual_parts", broken)
    with pytest.raises(ResidualLayoutError, match=r"sample W20-D45, test T5, signal y"):
        ev.parts([(1, p.with_(C=p.C * 1.1))])


def test_a_diagnosis_of_the_bug_reports_data_says_none(prepared):
    """The done criterion of the bug report, on its reduced copy: no crash, verdict none (two workers)."""
    from harness.analysis.diagnosis import diagnose
    d = diagnose(read_dataset(FIXTURE), DiagnoseSettings(workers=2))
    assert d.cause == "none" and d.verdict == "none", d.verdict
    assert not d.remainder.get("present"), d.remainder


@pytest.mark.parametrize("rate_hz, q", [(100.0, 1), (500.0, 1), (2000.0, 1), (2500.0, 1), (5000.0, 2),
                                        (10000.0, 5), (20000.0, 10)])
def test_fast_rigs_are_simulated_and_compared_at_about_2_kHz(rate_hz, q):
    """q = floor(rate / 2 kHz): the simulation period is q sample periods and the fit residuals fall on every q-th
    sample (fine part) and every 4 q-th (coarse part); traces and held-out tests keep every sample."""
    from types import SimpleNamespace
    from harness.analysis.diagnosis.jobs import decimation, step_offsets
    dt = 1.0 / rate_hz
    assert decimation(dt, 2000.0) == q
    n = int(round(3.0 * rate_hz)) + 1
    test = SimpleNamespace(t=np.arange(n) * dt, k_on=int(round(0.2 * rate_hz)), dt=dt)
    j = step_offsets(test, 0.5, COARSE_OUT, q)
    n_loc = n - test.k_on
    assert j[0] == 0 and np.all(j % q == 0) and np.all(np.diff(j) > 0) and j[-1] <= n_loc - 1
    fine = j[j <= round(0.5 * rate_hz)]
    assert np.all(np.diff(fine) == q) and np.all(np.diff(j[len(fine) - 1:]) == COARSE_OUT * q)
    # hand count: 1 + 0.5 s at rate/q, then (rest) / (4 q)
    n_fine = round(0.5 * rate_hz / q)
    assert j.size == n_fine + 1 + ((n_loc - 1) // q - n_fine) // COARSE_OUT
    np.testing.assert_array_equal(step_offsets(test, None, COARSE_OUT, q), np.arange(n_loc))


def test_structure_allows_for_an_uncertain_noise_level():
    """z = (chi2 - n) / sqrt(2 n + (2 e n)^2), e the relative standard uncertainty of the noise level (hand-computed:
    n = 21, chi2 = 63: e = 0 gives 42 / sqrt(42) = 6.48, above the threshold 5; e = 0.39 gives 42 / sqrt(42 +
    (2 * 0.39 * 21)^2) = 2.40: a reading noise estimated from 7-gap sweeps must not read as structure)."""
    from harness.analysis.diagnosis.fitting import ModelFit
    from harness.analysis.diagnosis.jobs import Chi2
    fit = {0: {("T7", "I"): Chi2(30.0, 10), ("T3", "y"): Chi2(12.0, 12)}, 1: {("T7", "I"): Chi2(33.0, 11)}}
    plain = ModelFit(effects=(), shared={}, base={}, params={}, fit_chi2=fit)
    assert plain.structure()[("T7", "I")] == pytest.approx(42 / 42 ** 0.5)
    unc = ModelFit(effects=(), shared={}, base={}, params={}, fit_chi2=fit, noise_rel_sd={("T7", "I"): 0.39})
    assert unc.structure()[("T7", "I")] == pytest.approx(42 / (42 + (2 * 0.39 * 21) ** 2) ** 0.5)
    assert unc.structure()[("T3", "y")] == plain.structure()[("T3", "y")] == 0.0


def test_a_cubic_drive_gets_sub_periods_only_where_the_spline_is_not_linear():
    """A raised-cosine drive (onset mid-record): at 105 Hz a 1.9 Hz drive's spline departs from the linear reading by
    about (w dt)^2 / 8 of its amplitude, 1.6e-3 (sub-periods needed); at 2 kHz a 1 Hz drive's by 1.2e-6 (the
    simulation's own period will do); a ramp is linear whatever the rate."""
    from harness.analysis.diagnosis.jobs import spline_is_linear
    for fs, f, linear in ((105.0, 1.9, False), (2000.0, 1.0, True), (500.0, 5.0, False)):
        t = np.arange(int(1.2 * fs)) / fs
        V = np.where(t >= 0.1, 11.5 * (1 - np.cos(2 * np.pi * f * (t - 0.1))), 0.0)
        assert spline_is_linear(V) == linear, (fs, f)
    assert spline_is_linear(np.linspace(0.0, 20.0, 50))
