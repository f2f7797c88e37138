"""Wall time of the whole diagnosis of the default dataset (issue target: at most 3 minutes on 2 cores).

Generates the main job's default dataset (the paper's 11 samples, the default hidden effect, seed 0)
through the FMU, then times ``harness.analysis.diagnosis.diagnose`` on it, blind (hidden effects and true
parameters removed from the manifest first), and prints the cause and the held-out gain.
Run from the repository root after ``make fmu``: ``python benchmarks/bench_diagnose.py``.
``--baseline-tree /work/wt-base`` then runs the same workload with that checkout's code (its own copy of
this script, in a subprocess with PYTHONPATH pointing there) and prints both wall times and their ratio.
"""
import argparse
import dataclasses
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.baseline import report, run_baseline  # noqa: E402
from harness.analysis import diagnosis  # noqa: E402
from harness.pipeline import DEFAULT_HIDDEN_EFFECT  # noqa: E402

from harness.sim import virtual_rig  # noqa: E402
from harness.data.dataset import read_dataset  # noqa: E402
from harness.sim.fmurun import default_fmu_path  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline-tree", help="checkout of the code to compare with (run after this one)")
    a = ap.parse_args(argv)
    fmu = default_fmu_path()
    if not fmu.exists():
        raise SystemExit(f"{fmu} not found: run `make fmu` first")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        virtual_rig.generate_dataset(Path(tmp) / "ds", seed=0, fmu_path=fmu, effects=DEFAULT_HIDDEN_EFFECT, progress=False)
        t_gen = time.perf_counter() - t0
        ds = read_dataset(Path(tmp) / "ds")
        ds = dataclasses.replace(ds, rig={k: v for k, v in ds.rig.items()
                                          if k not in ("effects", "true_parameters", "effect_definitions", "seed")})
        t0 = time.perf_counter()
        diag = diagnosis.diagnose(ds, diagnosis.DiagnoseSettings(workers=2))
        t_diag = time.perf_counter() - t0
    ov = diag.gain["overall_normalized_rmse"]
    print(f"default dataset: {len(ds.samples)} samples, hidden {DEFAULT_HIDDEN_EFFECT}, generated in {t_gen:.1f} s "
          f"(not part of the diagnosis); load average {os.getloadavg()[0]:.2f}")
    print(f"diagnosis (blind): cause = {diag.cause}; held-out RMSE in noise floors {ov['before']:.3g} -> {ov['after']:.3g}")
    print(f"wall time of the whole diagnosis: {t_diag:.1f} s (target <= 180 s)")
    if a.baseline_tree:
        t_base, out = run_baseline(a.baseline_tree, "bench_diagnose.py", [],
                                   r"wall time of the whole diagnosis: ([0-9.]+) s")
        print("baseline output:\n  " + "\n  ".join(out.strip().splitlines()))
        report("whole diagnosis (blind), wall time", t_diag, t_base, a.baseline_tree)


if __name__ == "__main__":
    main()
