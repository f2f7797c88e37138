"""Benchmark: identification of the nine training samples with the paper's NSGA-II settings.

    python benchmarks/bench_identify.py [--pop 200] [--gen 200] [--workers 2] [--seed 0] [--baseline-tree DIR]

1. Builds the virtual rig's dataset in memory (harness.sim.virtual_rig.generate_sample, simulated with
   the in-process model (fmu_src.model) instead of the FMU; not timed as identification).
2. Identifies the nine training samples (harness.analysis.identification.identify.identify_dataset, population 200,
   200 generations, 2 processes) and prints the wall time and the error of every parameter
   against the rig's true values.
3. On one sample, the cost of evaluating one candidate (C, m), i.e. simulating T3 and T5
   and computing the four objectives: naive (one scipy solve_ivp of the full model per
   test and candidate, metrics.step_metrics) against batched (one generation of 200
   candidates through harness.sim.population), and their ratio.
4. With ``--baseline-tree /work/wt-base``: the same workload with that checkout's code (its own copy of
   this script, in a subprocess with PYTHONPATH pointing there), both wall times and their ratio.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.baseline import report, run_baseline  # noqa: E402
from fmu_src.diaphragm import acceleration  # noqa: E402
from fmu_src.field import make_kernel  # noqa: E402
from harness.analysis.identification import identify  # noqa: E402
from harness.analysis.core import metrics  # noqa: E402
from harness.data import rig  # noqa: E402
from harness.sim import virtual_rig
from harness.data.dataset import Dataset, Sample  # noqa: E402



def _make(args):
    w, d, seed = args
    # in-process model instead of the FMU (same code)
    sid, p, tests = virtual_rig.generate_sample(w, d, seed=seed, simulator=virtual_rig.ModelSimulator())
    return Sample(id=sid, wt_pct=float(w), diameter_mm=float(d), thickness_mm=rig.THICKNESS_MM, tests=tests), p


def build_dataset(seed: int, workers: int):
    with ProcessPoolExecutor(max_workers=workers) as pool:
        made = list(pool.map(_make, [(w, d, seed) for w, d in rig.TRAINING_SAMPLES]))
    samples = [s for s, _ in made]
    truth = {s.id: p for s, p in made}
    ds = Dataset(root=None, synthetic=True, description="virtual rig, in memory", rig=rig.rig_description(),
                 samples=samples)
    return ds, truth


def naive_objectives(sample, params, C, m, settings, rig_desc):
    """Objectives of one candidate with scipy.integrate.solve_ivp per test (the obvious way)."""
    from scipy.integrate import solve_ivp
    out = []
    sigma = rig_desc["sensors"]["displacement_mm"]["noise_sigma"]
    for name in ("T3", "T5"):
        ts = sample.tests[name]
        t, V = ts.time_s, ts.voltage_V
        r0 = ts.gap_mm / 1000.0
        G = make_kernel(params.a, params.D, params.kB, r0)
        p = params

        def rhs(tt, y):
            k = min(max(int((tt - t[0]) / (t[1] - t[0]) + 1e-9), 0), t.size - 1)
            I, x, v = y
            F = p.Em * I * I * G(r0 - x)
            return [(V[k] - p.R * I) / p.L, v, acceleration(x, v, F, p.K1, p.K2, C, m)]

        sol = solve_ivp(rhs, (t[0], t[-1]), [0.0, 0.0, 0.0], t_eval=t, rtol=1e-7, atol=1e-10, max_step=0.01)
        x_mm = np.minimum(sol.y[1], r0) * 1e3
        t_on = float(t[np.argmax(V > 0.5 * V.max())])
        met = metrics.step_metrics(t, ts.displacement_mm, x_mm, t_step=t_on, noise_sigma=sigma)
        out += [met["ste_s"], met["rmse_mm"]]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pop", type=int, default=200)
    ap.add_argument("--gen", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0, help="seed of the virtual rig's noise")
    ap.add_argument("--naive", type=int, default=20, help="candidates for the naive timing")
    ap.add_argument("--progress", action="store_true")
    ap.add_argument("--baseline-tree", help="checkout of the code to compare with (run after this one)")
    a = ap.parse_args(argv)

    t0 = time.perf_counter()
    ds, truth = build_dataset(a.seed, a.workers)
    print(f"dataset: {len(ds.samples)} training samples built in memory in {time.perf_counter() - t0:.1f} s "
          f"(virtual rig, seed {a.seed}, in-process model, not through the FMU)")

    settings = identify.IdentifySettings(pop_size=a.pop, n_gen=a.gen)
    t0 = time.perf_counter()
    res = identify.identify_dataset(ds, settings, progress=a.progress, workers=a.workers)
    wall = time.perf_counter() - t0
    n_eval = sum(r.evaluations for r in res.values())
    cpu = sorted({round(r.timing_s.get("process_cpu_s", float("nan")), 3) for r in res.values()})
    print(f"identification: {len(res)} samples, population {a.pop}, {a.gen} generations, {a.workers} processes: "
          f"{wall:.1f} s wall ({n_eval} candidate evaluations, T3 + T5 each)")
    print(f"  CPU time of the worker processes: {', '.join(f'{c:.1f} s' for c in cpu)} "
          f"(the wall time on an otherwise idle machine is about the largest; load average now "
          f"{os.getloadavg()[0]:.2f})")
    names = ("R", "L", "Em", "K1", "K2", "C", "m")
    print("error vs true parameters [%]: " + "  ".join(f"{n:>6s}" for n in names))
    for sid, r in res.items():
        p = truth[sid]
        print(f"  {sid:8s}                     " + "  ".join(
            f"{100 * (getattr(r.params, n) / getattr(p, n) - 1):+6.2f}" for n in names))

    # ---- per-candidate cost: naive vs batched, on one sample
    sid = "W20-D45"
    sample = ds.sample(sid)
    an = identify.analyse_sample(sample, ds.rig, settings)
    obj = identify.objective_for(an, ds.rig, settings)
    front = res[sid].pareto
    X = obj.encode(front.C, front.m)          # the final front: a population of a late generation
    reps = 5
    identify.evaluate_many([obj], [X])        # warm-up (current tables)
    t0 = time.perf_counter()
    for _ in range(reps):
        Fb = identify.evaluate_many([obj], [X])[0]
    t_batch = (time.perf_counter() - t0) / reps / X.shape[0]
    C, m = obj.decode(X)
    idx = np.linspace(0, X.shape[0] - 1, a.naive).astype(int)
    t0 = time.perf_counter()
    Fn = [naive_objectives(sample, an.params, float(C[i]), float(m[i]), settings, ds.rig) for i in idx]
    t_naive = (time.perf_counter() - t0) / len(idx)
    Fn = np.array(Fn)
    dr = np.max(np.abs(Fn[:, [1, 3]] - Fb[idx][:, [1, 3]]) / Fb[idx][:, [1, 3]])
    print(f"per-candidate evaluation ({sid}, T3 + T5, 4 objectives): naive solve_ivp {t_naive * 1e3:.1f} ms "
          f"({len(idx)} candidates), batched {t_batch * 1e3:.3f} ms (one generation of {X.shape[0]} candidates "
          f"of this sample alone), ratio {t_naive / t_batch:.0f}x")
    t_run = sum(r.timing_s["evaluation_s"] for r in res.values()) / max(n_eval, 1)
    print(f"  batched, averaged over the whole nine-sample run (all generations, samples of a process "
          f"integrated together): {t_run * 1e3:.3f} ms per candidate, ratio {t_naive / t_run:.0f}x")
    print(f"  (largest relative RMSE difference naive vs batched over those candidates: {dr:.1e})")
    print(f"wall time of the nine-sample identification: {wall:.1f} s (target <= 60 s)")
    if a.baseline_tree:
        args = ["--pop", str(a.pop), "--gen", str(a.gen), "--workers", str(a.workers), "--seed", str(a.seed),
                "--naive", str(a.naive)]
        t_base, out = run_baseline(a.baseline_tree, "bench_identify.py", args,
                                   r"wall time of the nine-sample identification: ([0-9.]+) s")
        print("baseline output:\n  " + "\n  ".join(out.strip().splitlines()))
        report("nine-sample identification, wall time", wall, t_base, a.baseline_tree)
    return 0


if __name__ == "__main__":
    sys.exit(main())
