"""Wall time of the diagnosis with and without the discovery stage, side by side in one run (issue 22's aim:
the whole diagnosis with discovery at most twice the one without).

Generates the main job's default dataset (the paper's 11 samples, the default hidden effect, seed 0) through
the FMU, then times ``harness.analysis.diagnosis.diagnose`` on it blind, once with ``discover=False`` and once
with ``discover=True`` (the default), alternating ``--repeat`` times, and prints both wall times (and CPU
times of this process and its worker processes: the machine may be shared), the verdicts and the ratio.
``--dataset DIR`` times a stored dataset instead (e.g. one with an effect outside the catalogue, where the
discovery runs); ``--samples N`` keeps the first N samples (a quicker workload).
Run from the repository root after ``make fmu``: ``python benchmarks/bench_discovery.py``.
"""
import argparse
import dataclasses
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness.analysis import diagnosis  # noqa: E402
from harness.data.dataset import read_dataset  # noqa: E402
from harness.pipeline import DEFAULT_HIDDEN_EFFECT  # noqa: E402
from harness.sim import virtual_rig  # noqa: E402
from harness.sim.fmurun import default_fmu_path  # noqa: E402

HIDDEN = ("effects", "true_parameters", "effect_definitions", "seed")


def _cpu() -> float:
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def timed(ds, discover: bool, workers: int):
    t0, c0 = time.perf_counter(), _cpu()
    diag = diagnosis.diagnose(ds, diagnosis.DiagnoseSettings(workers=workers, discover=discover))
    return time.perf_counter() - t0, _cpu() - c0, diag


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataset", help="a stored dataset directory instead of the generated default one")
    ap.add_argument("--samples", type=int, help="keep only the first N samples")
    ap.add_argument("--repeat", type=int, default=1, help="alternating runs of each (default 1)")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        if a.dataset:
            src, what = Path(a.dataset), a.dataset
        else:
            fmu = default_fmu_path()
            if not fmu.exists():
                raise SystemExit(f"error: {fmu} not found: run `make fmu` first")
            src, what = Path(tmp) / "ds", f"default dataset (hidden {dict(DEFAULT_HIDDEN_EFFECT)}, seed 0)"
            virtual_rig.generate_dataset(src, seed=0, fmu_path=fmu, effects=DEFAULT_HIDDEN_EFFECT, progress=False)
        ds = read_dataset(src)
        ds = dataclasses.replace(ds, rig={k: v for k, v in ds.rig.items() if k not in HIDDEN})
        if a.samples:
            ds = dataclasses.replace(ds, samples=ds.samples[: a.samples])
        rows = {False: [], True: []}
        for _ in range(a.repeat):
            for disc in (False, True):
                rows[disc].append(timed(ds, disc, a.workers))
    print(f"{what}: {len(ds.samples)} samples; load average {os.getloadavg()[0]:.2f}; workers {a.workers}")
    for disc in (False, True):
        w = min(r[0] for r in rows[disc])
        c = min(r[1] for r in rows[disc])
        d = rows[disc][0][2]
        ov = d.gain["overall_normalized_rmse"]
        print(f"  discovery {'on ' if disc else 'off'}: wall {w:7.1f} s, CPU {c:7.1f} s; verdict {d.verdict!r}; "
              f"held-out RMSE / noise floor {ov['before']:.3g} -> {ov['after']:.3g}; "
              f"discovery step {d.timing_s.get('discovery', 0.0):.1f} s")
    w_off, w_on = min(r[0] for r in rows[False]), min(r[0] for r in rows[True])
    c_off, c_on = min(r[1] for r in rows[False]), min(r[1] for r in rows[True])
    print(f"ratio with / without discovery: wall {w_on / w_off:.2f}, CPU {c_on / c_off:.2f} (aim: <= 2)")


if __name__ == "__main__":
    main()
