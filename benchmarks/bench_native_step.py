"""doStep cost of the native FMU (``build_fmu.py --native``) against the pythonfmu FMU and an empty pythonfmu FMU.

    python benchmarks/bench_native_step.py [--sim-time 1.0] [--repeats 9]

In one run it builds (into a temp dir) mpc_actuator_native.fmu, mpc_actuator.fmu (with the status shim) and the
trivial pythonfmu FMU of benchmarks/bench_fmu_step.py (one input, one output, no physics; with the same status
shim, and pythonfmu's stock binary), then times through fmpy's FMU2Slave, interleaved, median of the repeats:

* "step": V constant (the default experiment), doStep alone;
* "sine": a 1 Hz sine of V, setReal(V) + doStep every 1 ms step (the input changes every step).

It prints microseconds per doStep and the ratio of the empty pythonfmu FMU's cost to the native FMU's
(target: >= 20). The fmpy call overhead (ctypes) is in every number alike.
"""
from __future__ import annotations

import argparse
import importlib.util
import math
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _bench_fmu_step():
    spec = importlib.util.spec_from_file_location("bench_fmu_step", REPO / "benchmarks" / "bench_fmu_step.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim-time", type=float, default=1.0, help="simulated seconds per measurement")
    ap.add_argument("--repeats", type=int, default=9, help="interleaved repetitions (median reported)")
    args = ap.parse_args(argv)
    b = _bench_fmu_step()
    n = int(round(args.sim_time / b.DT))
    V0 = 0.23 / 0.29 * 15.0
    V_sine = V0 * (1.0 + 0.5 * np.sin(2 * math.pi * np.arange(n + 1) * b.DT))
    tmp = Path(tempfile.mkdtemp(prefix="bench_native_"))
    try:
        fmus = b.build_fmus(tmp)
        fmus["native"] = tmp / "mpc_actuator_native.fmu"
        subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--native", "--out", str(fmus["native"])],
                       cwd=REPO, check=True, capture_output=True)
        keys = ("native", "mpc", "trivial", "trivial stock")
        ld = {k: b.Loaded(fmus[k], tmp, k) for k in keys}
        for f in ld.values():   # warm-up
            f.direct_loop(50)
            f.direct_loop(50, V_sine)
        times = {(k, s): [] for k in keys for s in ("step", "sine")}
        for _ in range(args.repeats):
            for k in keys:
                times[(k, "step")].append(ld[k].direct_loop(n) / n)
                times[(k, "sine")].append(ld[k].direct_loop(n, V_sine) / n)
        med = {key: statistics.median(v) * 1e6 for key, v in times.items()}
        print(f"doStep cost, 1 ms steps, {n} steps x {args.repeats} repeats (median, microseconds per step, "
              "through fmpy's FMU2Slave):")
        print(f"{'FMU':<38}{'step (V const)':>16}{'sine (setReal+doStep)':>24}")
        names = {"native": "native (mpc_actuator_native.fmu)", "mpc": "pythonfmu (mpc_actuator.fmu, shim)",
                 "trivial": "empty pythonfmu FMU (shim)", "trivial stock": "empty pythonfmu FMU (stock)"}
        for k in keys:
            print(f"{names[k]:<38}{med[(k, 'step')]:>16.3f}{med[(k, 'sine')]:>24.3f}")
        for s in ("step", "sine"):
            print(f"{s}: empty pythonfmu FMU (shim) / native = {med[('trivial', s)] / med[('native', s)]:.1f}x, "
                  f"empty (stock) / native = {med[('trivial stock', s)] / med[('native', s)]:.1f}x, "
                  f"pythonfmu actuator / native = {med[('mpc', s)] / med[('native', s)]:.1f}x (target: empty / "
                  f"native >= 20x)")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
