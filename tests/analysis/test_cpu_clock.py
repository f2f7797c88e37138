"""The fits' budget clock (``harness.analysis.core.cpu_clock``) counts CPU time along the critical path, so that a
verdict does not depend on the machine's load (issue "Any valid dataset": the fit budget was wall time, and a
20 kHz dataset's verdict changed with the load).

Checked against the operating system's own accounting: waiting (sleep, a blocked pipe) does not advance the
clock; CPU work does, by about what ``os.times`` says; a forked child starts at its parent's reading; and a
Levenberg-Marquardt fit whose residuals wait is not cut short by a budget shorter than its waiting."""
from __future__ import annotations

import os
import time

import numpy as np

from harness.analysis.core import cpu_clock
from harness.analysis.core.lsq import BoxProblem, LMSettings, levenberg_marquardt


def _spin(seconds: float) -> None:
    """Work for ``seconds`` [s] of this process's CPU time (as the OS counts it: ``os.times``)."""
    t = os.times()
    end = t.user + t.system + seconds
    x = 0.0
    while True:
        for _ in range(10000):
            x += 1.0
        t = os.times()
        if t.user + t.system >= end:
            return


def test_waiting_does_not_advance_the_clock_and_work_does():
    time.sleep(0.3)                  # (the BLAS threads spin a moment after numpy's start: let them settle)
    t0, os0 = cpu_clock.now(), os.times()
    time.sleep(0.3)
    assert cpu_clock.now() - t0 < 0.05
    t1 = cpu_clock.now()
    _spin(0.3)
    os1 = os.times()
    used = (os1.user + os1.system) - (os0.user + os0.system)
    assert abs((cpu_clock.now() - t1) - used) < 0.08          # about what the OS accounted
    assert cpu_clock.now() - t1 > 0.1                         # (a wall-clock-free spin still costs CPU)


def test_a_forked_child_starts_from_its_parents_reading_and_the_parent_advances_to_it():
    _spin(0.2)
    r, w = os.pipe()
    before = cpu_clock.now()
    pid = os.fork()
    if pid == 0:                                              # child: report its reading after 0.3 s of work
        try:
            start = cpu_clock.now()
            _spin(0.3)
            os.write(w, f"{start!r} {cpu_clock.now()!r}".encode())
        finally:
            os._exit(0)
    os.close(w)
    start_s, end_s = (float(v) for v in os.read(r, 200).decode().split())
    os.close(r)
    os.waitpid(pid, 0)
    assert before - 0.01 <= start_s <= before + 0.1           # the child did not start from 0
    assert end_s - start_s > 0.2
    assert cpu_clock.now() < end_s                            # the parent waited (no CPU) ...
    cpu_clock.advance_to(end_s)
    assert abs(cpu_clock.now() - end_s) < 0.02                # ... and now reads the branch's end
    cpu_clock.advance_to(end_s - 5.0)                         # never backwards
    assert cpu_clock.now() >= end_s


def test_a_fit_whose_residuals_wait_is_not_cut_short_by_the_budget():
    """Residuals that wait 150 ms per call (as under a loaded machine or a slow host) with a 250 ms budget: on
    the CPU clock the fit converges; on a wall clock it would stop after its first iteration."""
    target = np.array([1.0, -2.0])

    def residuals(pts):
        time.sleep(0.15)
        return [x - target for _, x in pts]

    box = BoxProblem(np.zeros(2), np.full(2, -10.0), np.full(2, 10.0), np.full(2, 1e-6), label="wait")
    res, = levenberg_marquardt([box], residuals, LMSettings(max_iter=20, deadline_s=cpu_clock.now() + 0.25))
    assert res.stop != "time_budget" and res.iterations >= 1
    assert np.allclose(res.x, target, atol=1e-4)


def test_a_fit_that_spends_its_budget_stops_on_it():
    def residuals(pts):
        _spin(0.03)
        return [np.array([x[0] ** 2 + 1.0, 10 * (x[1] - x[0] ** 2)]) for _, x in pts]

    box = BoxProblem(np.array([3.0, -3.0]), np.full(2, -10.0), np.full(2, 10.0), np.full(2, 1e-6), label="spin")
    res, = levenberg_marquardt([box], residuals, LMSettings(max_iter=200, ftol=0.0, atol=0.0,
                                                            deadline_s=cpu_clock.now() + 0.1))
    assert res.stop == "time_budget" and res.iterations < 10


def test_the_candidate_fits_in_worker_processes_advance_the_parents_clock(monkeypatch):
    """``fit_candidates`` spreads models over forked workers; the parent's clock afterwards reads at least the
    CPU time of the slowest worker (the critical path), not only its own waiting."""
    from harness.analysis.diagnosis import fitting

    from types import SimpleNamespace

    def busy(ctx, models, reference=None):
        _spin(0.3 * len(models))
        ctx.ev.dear_s_per_sim = 0.1 * len(models)      # what this worker's simulations cost at the dearest
        return list(models)

    monkeypatch.setattr(fitting, "fit_and_evaluate", busy)
    models = [fitting.ModelSpec((), {}, None) for _ in range(3)]
    ctx = SimpleNamespace(ev=SimpleNamespace(dear_s_per_sim=0.05))
    t0 = cpu_clock.now()
    out = fitting.fit_candidates(ctx, models, workers=2)
    assert len(out) == 3
    # the workers spun 0.6 s and 0.3 s in parallel: the critical path is about 0.6 s of CPU
    assert 0.5 < cpu_clock.now() - t0 < 1.5
    # and the dearest simulation cost of any worker comes back to price the next round (FitContext.round_cost_s)
    assert ctx.ev.dear_s_per_sim == 0.2
