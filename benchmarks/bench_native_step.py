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


DRIVER_SRC = r"""
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
typedef void *C;
typedef struct { void (*logger)(void *, const char *, int, const char *, const char *, ...);
                 void *(*alloc)(size_t, size_t); void (*free_)(void *); void (*fin)(void *, int); void *env; } CB;
static void logger(void *e, const char *n, int s, const char *c, const char *m, ...) {
    (void)e; (void)c; va_list ap; va_start(ap, m); fprintf(stderr, "[%s %d] ", n, s); vfprintf(stderr, m, ap);
    fputc('\n', stderr); va_end(ap); }
static double now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
static int cmp(const void *a, const void *b) { double x = *(const double *)a, y = *(const double *)b; return (x > y) - (x < y); }
/* driver LIB GUID RESOURCE_URI VR_INPUT N REPEATS SINE: median ns per doStep (instantiation not timed) */
int main(int argc, char **argv) {
    if (argc != 8) return 1;
    void *h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!h) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    C (*inst)(const char *, int, const char *, const char *, const CB *, int, int) = dlsym(h, "fmi2Instantiate");
    int (*setup)(C, int, double, double, int, double) = dlsym(h, "fmi2SetupExperiment");
    int (*enter)(C) = dlsym(h, "fmi2EnterInitializationMode"), (*exit_)(C) = dlsym(h, "fmi2ExitInitializationMode");
    int (*setr)(C, const unsigned *, size_t, const double *) = dlsym(h, "fmi2SetReal");
    int (*step)(C, double, double, int) = dlsym(h, "fmi2DoStep");
    void (*freei)(C) = dlsym(h, "fmi2FreeInstance");
    unsigned vr = (unsigned)atoi(argv[4]);
    long n = atol(argv[5]), reps = atol(argv[6]);
    int sine = atoi(argv[7]);
    double dt = 1e-3, *per = malloc(reps * sizeof(double)), *V = malloc((n + 1) * sizeof(double));
    for (long k = 0; k <= n; k++) V[k] = 11.9 * (1.0 + 0.5 * sin(2 * 3.141592653589793 * k * dt));
    CB cb = {logger, calloc, free, NULL, NULL};
    for (long r = 0; r < reps; r++) {
        C c = inst("bench", 1, argv[2], argv[3], &cb, 0, 0);
        if (!c) return 3;
        if (setup(c, 0, 0.0, 0.0, 0, 0.0) || enter(c) || exit_(c)) return 4;
        double t0 = now();
        for (long k = 0; k < n; k++) {
            if (sine) setr(c, &vr, 1, &V[k]);
            if (step(c, k * dt, dt, 1)) return 5;
        }
        per[r] = (now() - t0) / n * 1e9;
        freei(c);
    }
    qsort(per, reps, sizeof(double), cmp);
    printf("%.1f\n", per[reps / 2]);
    return 0;
}
"""


def c_driver_ns(driver: Path, loaded, n: int, repeats: int, sine: bool, env: dict) -> float:
    """Median ns per doStep measured in C (the driver loops over fmi2DoStep itself: no Python in between)."""
    md = loaded.md
    ident = md.coSimulation.modelIdentifier
    lib = Path(loaded.unzipdir) / "binaries" / "linux64" / f"{ident}.so"
    vin = loaded.vr.get("V", loaded.vr.get("u"))
    uri = (Path(loaded.unzipdir) / "resources").resolve().as_uri()
    proc = subprocess.run([str(driver), str(lib), md.guid, uri, str(vin), str(n), str(repeats), str(int(sine))],
                          capture_output=True, text=True, env=env, timeout=600)
    if proc.returncode != 0:
        raise SystemExit(f"bench driver failed on {ident} ({proc.returncode}):\n{proc.stderr[-2000:]}")
    return float(proc.stdout.strip())


def python_host_env() -> dict:
    """What a C host needs to run a pythonfmu FMU with this Python (tests/fmu/test_c_host.py's host_env)."""
    import os
    import sysconfig
    libpython = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("LDLIBRARY")
    site = list(dict.fromkeys([sysconfig.get_path("purelib"), sysconfig.get_path("platlib")]))
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON") and k != "LD_PRELOAD"}
    env.update(LD_PRELOAD=str(libpython), PYTHONHOME=sys.base_prefix, PYTHONPATH=os.pathsep.join(site))
    return env


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
        sys.path.insert(0, str(REPO))
        import build_fmu
        driver = tmp / "bench_driver"
        (tmp / "bench_driver.c").write_text(DRIVER_SRC)
        subprocess.run([*build_fmu.find_c_compiler(), "-std=c99", "-O2", "-o", str(driver), str(tmp / "bench_driver.c"),
                        "-ldl", "-lm"], check=True)
        envs = {k: ({} if k == "native" else python_host_env()) for k in keys}
        cns = {(k, s): c_driver_ns(driver, ld[k], n, args.repeats, s == "sine", envs[k]) for s in ("step", "sine")
               for k in keys}
        print(f"doStep cost, 1 ms steps, {n} steps x {args.repeats} repeats (median, microseconds per step, "
              "through fmpy's FMU2Slave):")
        print(f"{'FMU':<38}{'step (V const)':>16}{'sine (setReal+doStep)':>24}")
        names = {"native": "native (mpc_actuator_native.fmu)", "mpc": "pythonfmu (mpc_actuator.fmu, shim)",
                 "trivial": "empty pythonfmu FMU (shim)", "trivial stock": "empty pythonfmu FMU (stock)"}
        for k in keys:
            print(f"{names[k]:<38}{med[(k, 'step')]:>16.3f}{med[(k, 'sine')]:>24.3f}")
        print(f"\nthe same measured in C (a C driver loops over fmi2DoStep; the native FMU run with an empty "
              f"environment), median ns per step:")
        print(f"{'FMU':<38}{'step (V const)':>16}{'sine (setReal+doStep)':>24}")
        for k in keys:
            print(f"{names[k]:<38}{cns[(k, 'step')]:>16.1f}{cns[(k, 'sine')]:>24.1f}")
        for s in ("step", "sine"):
            print(f"C, {s}: empty pythonfmu FMU (shim) / native = {cns[('trivial', s)] / cns[('native', s)]:.1f}x, "
                  f"empty (stock) / native = {cns[('trivial stock', s)] / cns[('native', s)]:.1f}x, pythonfmu "
                  f"actuator / native = {cns[('mpc', s)] / cns[('native', s)]:.1f}x (target: empty / native >= 20x)")
        print("\nthrough fmpy (Python loop; ctypes overhead in every number):")
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
