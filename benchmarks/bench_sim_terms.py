"""harness.sim wall time on a diagnosis-like batch of the paper model (every term of fmu_src.terms off), this tree
against a baseline tree, side by side: the term set must cost nothing while it is off.

108 constant-voltage runs (3 fillers x 3 diameters x 12 gaps, a quarter blocked), 2.8 s, fine part 0.5 s at 1 ms;
best of 5 after a warm-up (compilation). ``python benchmarks/bench_sim_terms.py --baseline-tree /work/main``
runs the workload in both trees alternately (subprocesses, PYTHONPATH on each) and prints both and the ratio.
"""
import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def workload() -> float:
    import numpy as np
    from harness.data import rig
    from harness.sim.settings import Schedule
    from harness.sim.simulator import PARAM_FIELDS, Runs, simulate
    ps = [rig.true_params(wt, d).with_(r0=float(r0)) for wt in (10, 20, 30) for d in (30, 45, 60)
          for r0 in np.linspace(0.002, 0.009, 12)]
    n = len(ps)

    def runs():
        par = {k: np.array([getattr(p, k, 0.0) for p in ps], dtype=float) for k in PARAM_FIELDS}
        return Runs(params=par, blocked=np.arange(n) % 4 == 0, V=np.linspace(4, 12, n), dt=1e-3)
    simulate(runs(), Schedule(t_end=2.8, fine_s=0.5))
    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        simulate(runs(), Schedule(t_end=2.8, fine_s=0.5))
        best = min(best, time.perf_counter() - t0)
    return best


def _in_tree(tree: Path) -> float:
    """workload() with harness and fmu_src imported from ``tree`` (this script's code, that tree's modules)."""
    code = (f"import sys; sys.path.insert(0, {str(tree)!r}); ns = {{'__name__': 'bench', '__file__': {str(Path(__file__).resolve())!r}}}; "
            f"exec(open({str(Path(__file__).resolve())!r}).read(), ns); import harness; "
            f"assert harness.__file__.startswith({str(tree)!r}), harness.__file__; print(ns['workload']())")
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, cwd=tree)
    return float(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline-tree", type=Path, help="a checkout to compare with (e.g. /work/main)")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    if a.baseline_tree is None:
        print(f"harness.sim, 108 runs, terms off: {workload() * 1e3:.1f} ms (best of 5)")
        return
    for r in range(a.rounds):
        base, this = _in_tree(a.baseline_tree.resolve()), _in_tree(HERE)
        print(f"round {r + 1}: baseline {base * 1e3:.1f} ms, this tree {this * 1e3:.1f} ms, ratio {this / base:.2f}")


if __name__ == "__main__":
    main()
