"""Solve time of the nonlinear MPC (harness.control.mpc) per control step, against the control period.

    python benchmarks/bench_mpc.py [--rate-hz 100] [--repeats 3] [--fmu mpc_actuator.fmu]

Target: at most 5 ms per step at a 100 Hz control rate on this 2-core machine. In one run: the MPC closes the
loop around the actuator FMU (fmpy, 1 ms plant steps) on the 2 Hz 0 -> 1 mm stroke and on a staircase toward
pull-in, ``repeats`` times each (the first solve, which loads numba's compiled code, is left out); printed:
median, 95th percentile and maximum solve time per step and their ratio to the control period, and the
share of steps over the period; and the same for the CPU time of the solving thread (the wall-clock tail on
a shared machine is other processes' time). The default horizon is 8 periods in 4 move blocks, 3 Levenberg-Marquardt
iterations (5 rollouts each through the FMU's compiled integrator).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from fmu_src.specs import Params  # noqa: E402
from harness.control.closedloop import LoopSettings, MpcLoop, run_loop, staircase_to_pull_in, stroke_profile  # noqa: E402
from harness.control.mpc import Mpc, MpcSettings  # noqa: E402
from harness.control.opmap import holdable_limit  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate-hz", type=float, default=100.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--fmu", default=str(REPO / "mpc_actuator.fmu"))
    args = ap.parse_args(argv)
    p = Params()
    period = 1.0 / args.rate_hz
    settings = MpcSettings(dt_s=period)
    every = int(round(period / 1e-3))
    profiles = {"stroke 2 Hz 0-1 mm": stroke_profile(1e-3, 2.0),
                "staircase to pull-in": staircase_to_pull_in(holdable_limit(p)[0])}
    print(f"MPC: horizon {settings.horizon} periods, blocks {settings.blocks}, {settings.iterations} LM iterations; "
          f"control period {1e3 * period:g} ms; plant: {Path(args.fmu).name} at 1 ms")
    all_s = []
    for name, prof in profiles.items():
        times, cpu = [], []
        for _ in range(args.repeats):
            loop = MpcLoop(Mpc(p, settings))
            t0 = time.perf_counter()
            run_loop(args.fmu, p, loop, prof, LoopSettings(dt_s=1e-3, every=every, horizon_points=settings.horizon + 1))
            wall = time.perf_counter() - t0
            times += loop.solve_s[1:]
            cpu += loop.solve_cpu_s[1:]
        s = np.array(times)
        all_s += times
        print(f"{name:24s} steps {s.size:5d}  median {1e3 * np.median(s):6.2f} ms  p95 {1e3 * np.percentile(s, 95):6.2f} ms"
              f"  max {1e3 * s.max():6.2f} ms  median/period {np.median(s) / period:5.3f}  over period "
              f"{100 * np.mean(s > period):4.1f} %  (last loop wall {wall:.2f} s)")
        c = np.array(cpu)
        print(f"{'  CPU time (own thread)':24s} steps {c.size:5d}  median {1e3 * np.median(c):6.2f} ms  p95 "
              f"{1e3 * np.percentile(c, 95):6.2f} ms  max {1e3 * c.max():6.2f} ms")
    s = np.array(all_s)
    print(f"{'all':24s} steps {s.size:5d}  median {1e3 * np.median(s):6.2f} ms  p95 {1e3 * np.percentile(s, 95):6.2f} ms"
          f"  max {1e3 * s.max():6.2f} ms")
    verdict = {True: "met", False: "NOT met"}
    print(f"target <= 5 ms per step at {args.rate_hz:g} Hz: median {verdict[bool(np.median(s) <= 5e-3)]}, "
          f"95th percentile {verdict[bool(np.percentile(s, 95) <= 5e-3)]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
