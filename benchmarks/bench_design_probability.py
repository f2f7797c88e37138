"""Benchmark: the probability of meeting the spec for N feasible designs, linearised (delta method) vs
Monte Carlo, side by side on one in-process Dask worker.

    python benchmarks/bench_design_probability.py [--designs 400] [--draws 32]

The designs: the first N feasible designs (stroke >= 0.5 mm) of a grid over the virtual rig's nine training
samples (true parameters, 1 % standard uncertainty on every parameter). Both methods go through the same
task runner (harness.analysis.design.run.linearised / monte_carlo): linearised = 6 evaluations per design
(nominal + 5 forward differences) and the surfaces' weights; Monte Carlo = ``--draws`` evaluations per design
and one surface fit per draw and (D, gap) block. Prints both wall times (measured one after the other in
this run), their ratio, and the largest difference of the probabilities.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness.analysis.identification import parameter_uncertainty as U  # noqa: E402
from harness.analysis.design.run import (DesignSettings, default_space, design, linearised,  # noqa: E402
                                         monte_carlo, surface_model)
from harness.analysis.design.space import Targets  # noqa: E402
from harness.analysis.core.sweep import ClusterSettings  # noqa: E402
from harness.data import rig  # noqa: E402


def training(sd_rel=0.01):
    out = {}
    for w, d in rig.TRAINING_SAMPLES:
        p = rig.true_params(w, d)
        mean = np.array([getattr(p, n) for n in U.PARAMS])
        sid = rig.sample_id(w, d)
        out[sid] = U.ParameterUncertainty(sid, float(w), float(d), p, np.diag((sd_rel * mean) ** 2))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--designs", type=int, default=400)
    ap.add_argument("--draws", type=int, default=32)
    a = ap.parse_args()
    from dask.distributed import LocalCluster
    tr = training()
    _, coil = surface_model(tr)
    targets = Targets(stroke_mm=0.5)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as c:
        where = (ClusterSettings(scheduler=c.scheduler_address, progress=False), None)
        res = design(tr, targets, default_space(tr, {}, 8), DesignSettings(refine=0, max_candidates=0), where[0])
        rows = [dict(r) for r in res.candidates[:a.designs]]
        st = DesignSettings(n_draws=a.draws)
        print(f"{len(rows)} feasible designs; load average {os.getloadavg()[0]:.2f}")
        t0 = time.perf_counter()
        linearised(tr, targets, rows, coil, st, where)
        t1 = time.perf_counter()
        monte_carlo(tr, targets, rows, coil, st, where)
        t2 = time.perf_counter()
    lin, mc = t1 - t0, t2 - t1
    d = max(abs(r["probability_linearised"] - r["probability_mc"]) for r in rows
            if r["probability_linearised"] is not None)
    print(f"linearised (delta method): {lin:7.2f} s  ({len(rows) / lin:8.1f} designs/s)")
    print(f"Monte Carlo, {a.draws} draws:    {mc:7.2f} s  ({len(rows) / mc:8.1f} designs/s)")
    print(f"ratio Monte Carlo / linearised: {mc / lin:.1f}; largest |P_lin - P_MC| {d:.3f} "
          f"(binomial sd of the MC at P = 0.5: {0.5 / np.sqrt(a.draws):.3f}); load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
