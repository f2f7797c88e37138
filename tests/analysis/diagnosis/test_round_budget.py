"""A round of candidate or discovery fits starts only when the fit budget left pays for one iteration of its fits
(``FitContext.round_cost_s``, ``FitContext.can_afford``).

Deep profile, session 20: a second discovery round of 13 terms at 10 kHz began with about 10 CPU-s of a 75 CPU-s
budget left; every fit was cut after 0 iterations (so screened out), yet every start point was simulated past the
deadline, and the diagnosis took 122.9 CPU-s. The context here is a real ``FitContext`` whose samples, evaluator
counts and clock are stand-ins, so the cost bound is checked against a count made by hand.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from harness.analysis.core import cpu_clock
from harness.analysis.diagnosis import DiagnoseSettings
from harness.analysis.diagnosis.candidates import BASE_KEYS, coil_radius_def, shared_defs
from harness.analysis.diagnosis.fitting import FitContext, ModelSpec
from harness.analysis.discovery import default_library


def _ctx(monkeypatch, *, n_samples=4, shared=(0, 1, 2), workers=2, n_sims=10, sim_cpu_s=5.0, now_s=100.0,
         left_s=50.0, nuisance=False):
    ctx = FitContext.__new__(FitContext)
    ctx.samples = [SimpleNamespace(sid=f"S{i}") for i in range(n_samples)]
    ctx.settings = DiagnoseSettings(workers=workers)
    ctx.shared_idx = list(shared)
    ctx.library = default_library()
    ctx.nuisance = [coil_radius_def(0.01)] if nuisance else []
    ctx.ev = SimpleNamespace(n_sims=n_sims, sim_cpu_s=sim_cpu_s, dear_s_per_sim=0.0)
    ctx.deadline_s = now_s + left_s
    monkeypatch.setattr(cpu_clock, "now", lambda: now_s)
    return ctx


def _specs(effect, count):
    return [ModelSpec((effect,), {}, None) for _ in range(count)]


@pytest.mark.parametrize("nuisance", [False, True])
@pytest.mark.parametrize("count, workers", [(1, 2), (3, 2), (4, 2), (5, 1), (7, 3)])
def test_round_cost_is_the_start_and_one_jacobian_of_the_dearest_process(monkeypatch, count, workers, nuisance):
    ctx = _ctx(monkeypatch, workers=workers, nuisance=nuisance)
    k = len(shared_defs(("coil_heating",))) + (1 if nuisance else 0)
    # by hand: a joint fit of 3 samples with 7 base parameters each and k shared ones has 21 + k Jacobian columns;
    # its start and its first Jacobian simulate each of the 3 samples 1 + 21 + k times; a process takes
    # ceil(count / workers) of the fits in lock-step; a simulation costs 5.0 / 10 CPU-s
    per_fit = 3 * (1 + len(BASE_KEYS) * 3 + k)
    expected = math.ceil(count / min(workers, count)) * per_fit * 0.5
    assert ctx.round_cost_s(_specs("coil_heating", count)) == pytest.approx(expected)


def test_the_dearest_batch_prices_the_round_once_measured(monkeypatch):
    ctx = _ctx(monkeypatch, workers=1)
    k = len(shared_defs(("coil_heating",)))
    sims = 3 * (22 + k)
    assert ctx.round_cost_s(_specs("coil_heating", 1)) == pytest.approx(sims * 0.5)   # the mean: 5.0 CPU-s over 10
    ctx.ev.dear_s_per_sim = 2.0                      # a batch of the fits cost 2 CPU-s a simulation
    assert ctx.round_cost_s(_specs("coil_heating", 1)) == pytest.approx(sims * 2.0)


def test_the_evaluator_keeps_the_dearest_cost_of_a_batch_large_enough(monkeypatch):
    """Evaluator.parts prices its batches on the CPU clock: the dearest cost per simulation of a batch of at least
    DEAR_MIN_BATCH simulations (a fake clock that advances 1 s per simulation, 3 s per batch overhead)."""
    from harness.analysis.diagnosis import fitting
    clock = {"t": 0.0}
    monkeypatch.setattr(cpu_clock, "now", lambda: clock["t"])

    def run_jobs(jobs, names, opts):
        clock["t"] += 3.0 + len(jobs)
        return [{} for _ in jobs]

    monkeypatch.setattr(fitting, "run_jobs", run_jobs)
    monkeypatch.setattr(fitting, "residual_parts", lambda sample, sim, names, c: {})
    monkeypatch.setattr(fitting, "param_key", lambda p: (p,))
    ev = fitting.Evaluator([SimpleNamespace(sid="S0")], ["T3"], DiagnoseSettings())
    n = fitting.DEAR_MIN_BATCH
    ev.parts([(0, q) for q in range(n - 1)])           # too small a batch to price a round
    assert ev.dear_s_per_sim == 0.0 and ev.n_sims == n - 1 and ev.sim_cpu_s == pytest.approx(3.0 + n - 1)
    ev.parts([(0, 100 + q) for q in range(n)])
    assert ev.dear_s_per_sim == pytest.approx((3.0 + n) / n)
    ev.parts([(0, 1000 + q) for q in range(4 * n)])    # cheaper per simulation: the dearest stays
    assert ev.dear_s_per_sim == pytest.approx((3.0 + n) / n)
    ev.parts([(0, 100 + q) for q in range(n)])          # all cached: nothing simulated, nothing priced
    assert ev.n_sims == n - 1 + n + 4 * n


def test_nothing_measured_or_nothing_joint_costs_nothing(monkeypatch):
    assert _ctx(monkeypatch, n_sims=0, sim_cpu_s=0.0).round_cost_s(_specs("coil_heating", 3)) == 0.0
    assert _ctx(monkeypatch).round_cost_s([ModelSpec((), {}, None)]) == 0.0      # no shared parameter: no joint fit


def test_a_round_starts_only_when_the_joint_fits_share_of_the_budget_left_pays_for_it(monkeypatch):
    # 2 specs, 2 workers: one fit per process, 3 * (22 + k) simulations at 0.5 CPU-s
    k = len(shared_defs(("coil_heating",)))
    cost = 3 * (22 + k) * 0.5
    # 3 of 4 samples share the fit: the joint fits have 3/4 of the budget left (FitContext.joint_share)
    assert _ctx(monkeypatch, left_s=cost / 0.75 * 1.001).can_afford(_specs("coil_heating", 2))
    assert not _ctx(monkeypatch, left_s=cost / 0.75 * 0.999).can_afford(_specs("coil_heating", 2))
    # every sample in the shared fit: the whole budget left is theirs
    assert _ctx(monkeypatch, n_samples=3, left_s=cost * 1.001).can_afford(_specs("coil_heating", 2))
    assert not _ctx(monkeypatch, n_samples=3, left_s=cost * 0.999).can_afford(_specs("coil_heating", 2))
    # a spent budget pays for nothing, not even a round that costs nothing measured
    assert not _ctx(monkeypatch, n_sims=0, sim_cpu_s=0.0, left_s=0.0).can_afford(_specs("coil_heating", 1))
    assert _ctx(monkeypatch, n_sims=0, sim_cpu_s=0.0, left_s=1e-3).can_afford(_specs("coil_heating", 1))


@pytest.mark.parametrize("rates_hz, max_rate_hz, expected_s", [
    ((10_000.0, 1000.0), 2000.0, 5e-4),     # 10 kHz compared at every 5th sample; 1 kHz at every one
    ((10_000.0, 3000.0), 2000.0, 1 / 3000),  # q = floor(3000 / 2000) = 1: 3 kHz compared at every sample
    ((20_000.0, 4500.0), 2000.0, 4.4444e-4),  # 20 kHz: q = 10 (5e-4 s); 4.5 kHz: q = 2 (4.444e-4 s)
    ((500.0, 250.0), 2000.0, 2e-3),
    ((10_000.0,), 1e9, 1e-4),               # no decimation below the rate limit
])
def test_lags_are_resolved_at_the_period_the_fits_compare_at(rates_hz, max_rate_hz, expected_s):
    from harness.analysis.diagnosis.jobs import shortest_compared_period_s
    tests = {f"T{3 + 2 * q}": SimpleNamespace(dt=1.0 / r) for q, r in enumerate(rates_hz)}
    tests["T1"] = SimpleNamespace(gaps=(1.0,))                 # a sweep has no sample period
    samples = [SimpleNamespace(tests=tests)]
    assert shortest_compared_period_s(samples, list(tests), max_rate_hz) == pytest.approx(expected_s, rel=1e-4)
    assert math.isnan(shortest_compared_period_s(samples, ["T1"], max_rate_hz))
