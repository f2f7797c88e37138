"""harness.sim CPU time of a batch with a Dahl friction term (``fmu_src.terms`` ``dahl_friction``, presliding lengths
1 um .. 1 mm) against the same batch of the paper model, side by side in one run (issue 22: a Dahl row used to cost
50 times a paper row at 10 um, its sub-steps sized from an a-priori speed bound 20-3000 times the motion's).

The batch: 108 constant-voltage runs (3 fillers x 3 diameters x 12 gaps, a quarter blocked), 2.8 s, fine part
0.5 s at 1 ms (as ``bench_sim_terms.py``); Dahl's coefficient 1/20 of its natural scale. Best of 3 after a warm-up.
Run from the repository root: ``python benchmarks/bench_sim_dahl.py``.
"""
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def cost(ps) -> float:
    import numpy as np
    from harness.sim.settings import Schedule
    from harness.sim.simulator import PARAM_FIELDS, Runs, simulate
    n = len(ps)
    runs = Runs(params={k: np.array([getattr(p, k, 0.0) for p in ps], dtype=float) for k in PARAM_FIELDS},
                blocked=np.arange(n) % 4 == 0, V=np.linspace(4, 12, n), dt=1e-3)
    simulate(runs, Schedule(t_end=2.8, fine_s=0.5))
    best = float("inf")
    for _ in range(3):
        c0 = time.process_time()
        simulate(runs, Schedule(t_end=2.8, fine_s=0.5))
        best = min(best, time.process_time() - c0)
    return best


def main() -> None:
    import numpy as np
    from fmu_src.terms import TERMS
    from harness.data import rig
    ps = [rig.true_params(wt, d).with_(r0=float(r0)) for wt in (10, 20, 30) for d in (30, 45, 60)
          for r0 in np.linspace(0.002, 0.009, 12)]
    t = TERMS["dahl_friction"]
    paper = cost(ps)
    print(f"paper model: {paper:.3f} s CPU")
    for x_c in (1e-6, 1e-5, 1e-4, 1e-3):
        d = cost([p.with_(**{t.coef.name: 0.05 * float(t.scale(p)), "tau_dahl": x_c}) for p in ps])
        print(f"Dahl friction, presliding length {x_c:g} m: {d:.3f} s CPU, {d / paper:.1f} x the paper model")


if __name__ == "__main__":
    main()
