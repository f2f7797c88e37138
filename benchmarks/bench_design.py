"""Benchmark: design evaluations on Dask, 1 and 2 local workers side by side, and the time for 10^6.

    python benchmarks/bench_design.py [--blocks 24] [--block-size 1000] [--full] [--scheduler ADDRESS]

A design evaluation is what ``mpc-actuator design`` computes per grid point
(harness.analysis.design.evaluate.evaluate_block): current, power, blocked force, the static operating
point (vectorized root find on the force balance) and a 0.5 s step response through the vectorized
simulator (harness.sim) with its 2 % settling time. The surfaces come from the virtual rig's nine training
samples (true parameters). Tasks are (D, gap) blocks of ``--block-size`` designs (wt% x V), run by
harness.analysis.core.sweep on a LocalCluster of processes (startup timed apart; one warm-up task per worker
first).

Prints: evaluations per second on 1 and on 2 workers (the same blocks, measured one after the other in
this run), the speed-up, the CPU time the tasks took in the workers (evaluations per CPU second: on a shared,
loaded machine the wall-clock rates measure the share of the cores this job got, not the code), the time for 10^6 evaluations extrapolated from the 2-worker rate, with
``--full`` that time measured (10^6 evaluations on 2 workers), and a scaling estimate for N workers:
t(N) = 10^6 / (N * r1 * e) with r1 the 1-worker rate and e the measured 2-worker efficiency, bounded by the
scheduler's ~1 ms per task (``--scheduler`` runs the same workload on an existing cluster instead).
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
from harness.analysis.design.run import DesignSettings, block_task, nominal_params, surface_model  # noqa: E402
from harness.analysis.design.space import Axis, DesignSpace  # noqa: E402
from harness.analysis.core.sweep import ClusterSettings, cluster_client, run_tasks  # noqa: E402
from harness.data import rig  # noqa: E402


def training():
    out = {}
    for w, d in rig.TRAINING_SAMPLES:
        p = rig.true_params(w, d)
        sid = rig.sample_id(w, d)
        out[sid] = U.ParameterUncertainty(sid, float(w), float(d), p, np.zeros((7, 7)))
    return out


def jobs_for(n_blocks: int, block_size: int):
    """n_blocks (D, gap) tasks of block_size designs (wt x V) over the rig's hull."""
    tr = training()
    fits, coil = surface_model(tr)
    n_w = 25
    n_v = max(1, block_size // n_w)
    n_d = max(1, int(round(np.sqrt(n_blocks))))
    n_g = int(np.ceil(n_blocks / n_d))
    space = DesignSpace(Axis("wt_pct", 10, 30, n_w), Axis("diameter_mm", 30, 60, n_d),
                        Axis("gap_mm", 4, 12, n_g), Axis("voltage_V", 1, 12, n_v))
    par = nominal_params(fits, space)
    st = DesignSettings()
    jobs = [(coil, float(d) / 1e3, float(g) / 1e3, {k: par[k][:, j] for k in par}, space.voltage_V.values, st)
            for j, d in enumerate(space.diameter_mm.values) for g in space.gap_mm.values]
    return jobs[:n_blocks], n_w * n_v


def cpu_task(args):
    """block_task and the CPU time [s] of the worker process it took (independent of other load)."""
    c0 = time.process_time()
    r = block_task(args)
    return r, time.process_time() - c0


def timed(jobs, client, settings):
    t0 = time.perf_counter()
    out = run_tasks(cpu_task, jobs, settings, desc="blocks", client=client)
    timed.cpu_s = sum(c for _, c in out)
    return time.perf_counter() - t0, [r for r, _ in out]


def rate_on(workers: int, jobs, per_block: int, scheduler=None):
    settings = ClusterSettings(workers=workers, scheduler=scheduler, progress=False)
    t0 = time.perf_counter()
    with cluster_client(settings) as client:
        start = time.perf_counter() - t0
        n_w = len(client.scheduler_info()["workers"])
        timed(jobs[:n_w], client, settings)                     # warm-up: imports, kernel caches
        wall, res = timed(jobs, client, settings)
    rate_on.cpu_s = timed.cpu_s
    return len(jobs) * per_block / wall, wall, start, res, n_w


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--blocks", type=int, default=24)
    ap.add_argument("--block-size", type=int, default=1000)
    ap.add_argument("--full", action="store_true", help="also run 10^6 evaluations on 2 workers")
    ap.add_argument("--scheduler", help="an existing Dask scheduler: measure there instead of 1 vs 2 local workers")
    a = ap.parse_args(argv)
    jobs, per_block = jobs_for(a.blocks, a.block_size)
    n_eval = len(jobs) * per_block
    print(f"workload: {len(jobs)} tasks (D x gap blocks) of {per_block} designs = {n_eval} evaluations "
          f"(static operating point + 0.5 s step response each); load average {os.getloadavg()[0]:.2f}")
    if a.scheduler:
        r, wall, start, _, n_w = rate_on(1, jobs, per_block, a.scheduler)
        print(f"cluster {a.scheduler} ({n_w} workers): {r:9.0f} evaluations/s ({wall:.1f} s); "
              f"10^6 evaluations: {1e6 / r / 60:.1f} min")
        return
    r1, w1, s1, res1, _ = rate_on(1, jobs, per_block)
    c1 = rate_on.cpu_s
    r2, w2, s2, res2, _ = rate_on(2, jobs, per_block)
    c2 = rate_on.cpu_s
    same = all(np.array_equal(x[k], y[k]) for x, y in zip(res1, res2) for k in x)
    print(f"1 worker : {r1:9.0f} evaluations/s  ({w1:.1f} s; cluster start {s1:.1f} s)")
    print(f"2 workers: {r2:9.0f} evaluations/s  ({w2:.1f} s; cluster start {s2:.1f} s)")
    print(f"speed-up 2 vs 1 worker: {r2 / r1:.2f}  (results identical: {same}); load average {os.getloadavg()[0]:.2f}")
    print(f"10^6 design evaluations on 2 workers, extrapolated: {1e6 / r2:.0f} s = {1e6 / r2 / 60:.1f} min "
          f"(target <= 10 min)")
    rc = n_eval / c1
    print(f"CPU time of the tasks: 1 worker {c1:.1f} s, 2 workers {c2:.1f} s -> {rc:.0f} evaluations per CPU second; "
          f"10^6 evaluations on 2 otherwise idle cores: {1e6 / (2 * rc):.0f} s = {1e6 / (2 * rc) / 60:.1f} min "
          f"(wall = CPU / 2 when nothing else runs)")
    eff = r2 / (2 * r1)
    task_s = w1 / len(jobs)
    for n in (4, 16, 64, 256):
        rate = min(n * r1 * eff, per_block / 1e-3)
        print(f"  estimate, {n:4d} workers (efficiency {eff:.2f}, {task_s * 1e3:.0f} ms per task on one worker): "
              f"{1e6 / rate:7.1f} s for 10^6")
    if a.full:
        full_jobs, per = jobs_for(int(np.ceil(1e6 / per_block)), a.block_size)
        r, wall, _, _, _ = rate_on(2, full_jobs, per)
        print(f"10^6 design evaluations on 2 workers, measured: {len(full_jobs) * per} evaluations in {wall:.0f} s "
              f"= {wall / 60:.1f} min ({r:.0f} evaluations/s; load average {os.getloadavg()[0]:.2f})")


if __name__ == "__main__":
    main()
