"""Cost of one FMI doStep of mpc_actuator.fmu at a 1 ms communication step, against a trivial pythonfmu FMU.

    python benchmarks/bench_fmu_step.py [--sim-time 1.0] [--repeats 5]

In one run it builds (into a temp dir) mpc_actuator.fmu (with the status shim,
as build_fmu.py does by default, and once more with --no-status-shim) and a
trivial pythonfmu FMU (one Real input u and one Real output that do_step sets to the time, no physics)
in two variants: pythonfmu's stock binary, and wrapped with the same status shim
(build_fmu.add_status_shim). Ratios are taken against the trivial FMU with the
shim, so both sides pay for the shim's extra call; the stock rows show what the
shim costs. Then it measures:

* direct loop (fmpy FMU2Slave, no recording): microseconds per doStep for all
  FMUs, repeated and interleaved, median reported, for two scenarios of V:
  "step" (V constant: the default experiment; doStep alone) and "sine" (1 Hz sine,
  setReal(V) before every doStep, so the input changes every step), against the
  trivial FMU doing the same (doStep alone; setReal(u) + doStep with the same sine),
  plus the cost of the setReal calls alone (a loop of setReal only) and the doStep
  of the sine scenario alone (each doStep timed by itself after its setReal, the
  timer's own cost subtracted; the same on both sides);
* the same through fmpy.simulate_fmu (which adds fmpy's input handling and the
  recording of every output at every step);
* the accuracy of the 1 ms and 20 ms runs against the independent reference of
  tests/fmu/test_fmu.py (scipy DOP853 with the quadrature force kernel).
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
import textwrap
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DT = 1e-3

TRIVIAL_SRC = textwrap.dedent('''\
    from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


    class TrivialFmu(Fmi2Slave):
        """One Real input u, one Real output y = time at the end of the step + 0*u; no physics."""

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.modelName = "trivial_fmu"
            self.u = 0.0
            self.y = 0.0
            self.register_variable(Real("u", causality=Fmi2Causality.input,
                                        variability=Fmi2Variability.continuous,
                                        description="input (read by do_step, like mpc_actuator's V)"))
            self.register_variable(Real("y", causality=Fmi2Causality.output,
                                        variability=Fmi2Variability.continuous,
                                        description="time at the end of the last step"))

        def do_step(self, current_time, step_size):
            self.y = current_time + step_size + 0.0 * self.u
            return True
''')


def build_fmus(tmp: Path) -> dict[str, Path]:
    """Build the FMUs in subprocesses (keeps the slave modules out of this process's sys.modules).

    Returns {"mpc": with the status shim, "mpc stock": --no-status-shim, "trivial": trivial FMU with the
    status shim, "trivial stock": pythonfmu's binary only}.
    """
    fmus = {"mpc": tmp / "mpc_actuator.fmu", "mpc stock": tmp / "stock" / "mpc_actuator.fmu"}
    for key, extra in (("mpc", []), ("mpc stock", ["--no-status-shim"])):
        subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--out", str(fmus[key]), *extra], cwd=REPO,
                       check=True, capture_output=True)
    src = tmp / "trivial_src"
    src.mkdir()
    (src / "trivial_fmu.py").write_text(TRIVIAL_SRC)
    fmus["trivial stock"] = tmp / "stock" / "trivial_fmu.fmu"
    subprocess.run([sys.executable, "-c",
                    "import sys; from pythonfmu.builder import FmuBuilder; "
                    "FmuBuilder.build_FMU(sys.argv[1], dest=sys.argv[2])", str(src / "trivial_fmu.py"),
                    str(fmus["trivial stock"])], cwd=tmp, check=True, capture_output=True)
    fmus["trivial"] = tmp / "trivial_fmu.fmu"
    shutil.copyfile(fmus["trivial stock"], fmus["trivial"])
    subprocess.run([sys.executable, "-c",
                    "import sys; sys.path.insert(0, sys.argv[1]); import build_fmu; "
                    "build_fmu.add_status_shim(sys.argv[2], 'trivial_fmu')", str(REPO), str(fmus["trivial"])],
                   cwd=tmp, check=True, capture_output=True)
    return fmus


class Loaded:
    def __init__(self, fmu: Path, tmp: Path, label: str):
        from fmpy import extract, read_model_description
        self.md = read_model_description(str(fmu))
        self.unzipdir = extract(str(fmu), unzipdir=str(tmp / (label.replace(" ", "_") + "_x")))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}

    def direct_loop(self, n: int, V=None, set_only: bool = False, step_only: bool = False) -> float:
        """Wall seconds of n doSteps of DT (setReal(V[k]) of the FMU's input before each step if V is given;
        with set_only, the n setReal calls alone; with step_only, the doStep calls alone: each one timed
        by itself, the setReal before it outside the timed part, minus the cost of an empty timed region)."""
        from fmpy.fmi2 import FMU2Slave
        f = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                      modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="bench")
        f.instantiate()
        f.setupExperiment(startTime=0.0)
        f.enterInitializationMode()
        vin = self.vr.get("V", self.vr.get("u"))
        if V is not None:
            f.setReal([vin], [float(V[0])])
        f.exitInitializationMode()
        do_step, set_real = f.doStep, f.setReal
        if V is None:
            t0 = time.perf_counter()
            for k in range(n):
                do_step(k * DT, DT)
            wall = time.perf_counter() - t0
        elif step_only:
            vrV = [vin]
            vals = [[float(v)] for v in V]
            pc = time.perf_counter
            wall = 0.0
            for k in range(n):
                set_real(vrV, vals[k])
                t0 = pc()
                do_step(k * DT, DT)
                wall += pc() - t0
            empty = 0.0
            for k in range(n):   # the timer's own cost, subtracted on both sides
                t0 = pc()
                empty += pc() - t0
            wall -= empty
        elif set_only:
            vrV = [vin]
            vals = [[float(v)] for v in V]
            t0 = time.perf_counter()
            for k in range(n):
                set_real(vrV, vals[k])
            wall = time.perf_counter() - t0
        else:
            vrV = [vin]
            vals = [[float(v)] for v in V]
            t0 = time.perf_counter()
            for k in range(n):
                set_real(vrV, vals[k])
                do_step(k * DT, DT)
            wall = time.perf_counter() - t0
        f.terminate()
        f.freeInstance()
        return wall

    def simulate(self, T: float, input_signal=None, start_values=None):
        from fmpy import simulate_fmu
        t0 = time.perf_counter()
        res = simulate_fmu(self.unzipdir, model_description=self.md, stop_time=T, output_interval=DT,
                           input=input_signal, start_values=start_values or {}, validate=False)
        return time.perf_counter() - t0, res


def load_reference():
    spec = importlib.util.spec_from_file_location("fmu_test_reference", REPO / "tests" / "fmu" / "test_fmu.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim-time", type=float, default=1.0, help="simulated seconds per measurement")
    ap.add_argument("--repeats", type=int, default=9, help="interleaved repetitions (median reported)")
    ap.add_argument("--baseline-tree", help="checkout of the code to compare with (its own copy of this script "
                                            "runs afterwards, on the FMU built in that checkout)")
    args = ap.parse_args(argv)
    T, n = args.sim_time, int(round(args.sim_time / DT))

    sys.path.insert(0, str(REPO))
    from fmu_src.specs import Params
    p = Params()
    V0 = 0.23 / p.kB * p.R
    t_grid = np.arange(n + 1) * DT
    V_sine = V0 * (1.0 + 0.5 * np.sin(2 * math.pi * 1.0 * t_grid))
    sig = np.zeros(n + 1, dtype=[("time", np.float64), ("V", np.float64)])
    sig["time"], sig["V"] = t_grid, V_sine

    tmp = Path(tempfile.mkdtemp(prefix="bench_fmu_"))
    try:
        fmus = build_fmus(tmp)
        ld = {k: Loaded(p, tmp, k) for k, p in fmus.items()}
        mpc, triv = ld["mpc"], ld["trivial"]

        # warm-up (imports, library loading, first-call costs)
        for f in ld.values():
            f.direct_loop(50)
        mpc.direct_loop(50, V_sine)
        triv.direct_loop(50, V_sine)

        # key -> (FMU, input): the status shim on both sides of every ratio; "stock" = pythonfmu's binary only
        cases = {"trivial stock": (ld["trivial stock"], None, {}), "trivial": (triv, None, {}),
                 "trivial sine": (triv, V_sine, {}), "trivial set": (triv, V_sine, {"set_only": True}),
                 "trivial sine step": (triv, V_sine, {"step_only": True}),
                 "mpc step stock": (ld["mpc stock"], None, {}), "mpc step": (mpc, None, {}),
                 "mpc sine": (mpc, V_sine, {}), "mpc set": (mpc, V_sine, {"set_only": True}),
                 "mpc sine step": (mpc, V_sine, {"step_only": True})}
        direct = {k: [] for k in cases}
        fmpy_t = {"trivial stock": [], "trivial": [], "trivial sine": [], "mpc step": [], "mpc sine": []}
        triv_sig = sig.copy()
        triv_sig.dtype.names = ("time", "u")
        for _ in range(args.repeats):
            for k, (f, V, how) in cases.items():
                direct[k].append(f.direct_loop(n, V, **how))
            fmpy_t["trivial stock"].append(ld["trivial stock"].simulate(T)[0])
            fmpy_t["trivial"].append(triv.simulate(T)[0])
            fmpy_t["trivial sine"].append(triv.simulate(T, input_signal=triv_sig)[0])
            fmpy_t["mpc step"].append(mpc.simulate(T)[0])
            fmpy_t["mpc sine"].append(mpc.simulate(T, input_signal=sig)[0])
        us = {k: statistics.median(v) / n * 1e6 for k, v in direct.items()}
        us_f = {k: statistics.median(v) / n * 1e6 for k, v in fmpy_t.items()}

        print(f"communication step {DT * 1e3:g} ms, {T:g} s simulated per run, median of {args.repeats} "
              "interleaved runs; ratios against the trivial FMU with the status shim")
        print("direct FMU2Slave loop (no recording):")
        print(f"  {'trivial pythonfmu FMU, stock binary':<44}: {us['trivial stock']:8.2f} us/doStep")
        print(f"  {'trivial pythonfmu FMU + status shim':<44}: {us['trivial']:8.2f} us/doStep")
        print(f"  {'trivial + shim, setReal(u) + doStep':<44}: {us['trivial sine']:8.2f} us/step"
              f"   (setReal alone {us['trivial set']:.2f} us)")
        print(f"  {'mpc_actuator, step, stock (--no-status-shim)':<44}: {us['mpc step stock']:8.2f} us/doStep")
        for sc, ref, label in (("mpc step", "trivial", "mpc_actuator, step (V constant), doStep"),
                               ("mpc sine", "trivial sine", "mpc_actuator, 1 Hz sine, setReal(V) + doStep")):
            print(f"  {label:<44}: {us[sc]:8.2f} us/step     ratio to trivial {us[sc] / us[ref]:6.2f}"
                  f"   {1.0 / (us[sc] * 1e-6) * DT:8.1f} simulated s per wall s")
        d_mpc, d_triv = us["mpc sine step"], us["trivial sine step"]
        print(f"  {'mpc_actuator, 1 Hz sine, doStep alone':<44}: {d_mpc:8.2f} us/doStep   ratio to trivial "
              f"{d_mpc / d_triv:6.2f}   (each doStep timed by itself after its setReal; trivial {d_triv:.2f} us)")
        print(f"  status shim cost per doStep: trivial {us['trivial'] - us['trivial stock']:+.2f} us, "
              f"mpc_actuator step {us['mpc step'] - us['mpc step stock']:+.2f} us")
        print("fmpy.simulate_fmu (input handling + recording of every output each step; excludes extraction):")
        print(f"  {'trivial pythonfmu FMU, stock binary':<44}: {us_f['trivial stock']:8.2f} us/step")
        print(f"  {'trivial pythonfmu FMU + status shim':<44}: {us_f['trivial']:8.2f} us/step")
        print(f"  {'trivial + shim, 1 Hz sine input u':<44}: {us_f['trivial sine']:8.2f} us/step")
        for sc, ref, label in (("mpc step", "trivial", "mpc_actuator, step (V constant)"),
                               ("mpc sine", "trivial sine", "mpc_actuator, 1 Hz sine (input signal)")):
            print(f"  {label:<44}: {us_f[sc]:8.2f} us/step     ratio to trivial "
                  f"{us_f[sc] / us_f[ref]:6.2f}   {1.0 / (us_f[sc] * 1e-6) * DT:8.1f} simulated s per wall s")

        # accuracy against the independent reference (default parameters, and pull-in at r0 = 3 mm)
        ref_mod = load_reference()
        print("accuracy vs reference (DOP853 rtol 1e-12, quadrature kernel; max|err| / max|ref|), "
              f"{T:g} s, FMU rtol = {ref_mod.RTOL:g} (its default):")
        for r0 in (p.r0, 0.003):
            for h in (1e-3, 20e-3):
                from fmpy import simulate_fmu
                res = simulate_fmu(mpc.unzipdir, model_description=mpc.md, stop_time=T, output_interval=h,
                                   start_values={"r0": r0}, validate=False)
                ref = ref_mod.reference_solution(p.with_(r0=r0), V0, res["time"], rtol=1e-12)
                ex = ref_mod.rel_err(res["x"], ref["x"])
                eI = ref_mod.rel_err(res["I"], ref["I"])
                print(f"  r0 = {r0 * 1e3:4.1f} mm, step {h * 1e3:4.0f} ms: x {ex:.2e}   I {eI:.2e}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if args.baseline_tree:
        from benchmarks.baseline import run_baseline
        ratio = us["mpc step"] / us["trivial"]
        base, out = run_baseline(args.baseline_tree, "bench_fmu_step.py", ["--repeats", str(args.repeats)],
                                 r"step \(V constant\), doStep\s*:\s*[0-9.]+ us/step\s+ratio to trivial\s+([0-9.]+)")
        print("baseline output:\n  " + "\n  ".join(out.strip().splitlines()))
        print(f"doStep (V constant) / trivial FMU's: this tree {ratio:.2f}, baseline ({args.baseline_tree}) "
              f"{base:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
