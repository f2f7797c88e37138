"""Cost of the diagnosis vs the sample rate: the same rig and samples at 1, 2.5, 5 and 10 kHz, side by side.

Issue target: the cost grows no faster than linearly with the number of samples (10 kHz data must not make
the diagnosis explode). Each dataset is made by the independent test-data generator
(``tests/independent/generator.py``: its own physics, our rig's conventions and noise except the sample
rate) with one hidden effect (``filler_saturation`` at magnitude 1) on the same samples, then diagnosed
blind (``harness.analysis.diagnosis.diagnose``, one worker process so that the timing is not the
scheduler's). Printed per rate: wall time of the diagnosis, samples in the dataset, simulated sample
intervals (runs x sample periods integrated by ``harness.sim.simulator``; counted by wrapping it), and the
time and the simulated intervals per dataset sample relative to the first rate (a ratio <= 1 at the
higher rates: at most linear).

Run from the repository root: ``python benchmarks/bench_diagnose_rate.py [--rates 1000 2500 5000 10000]
[--samples W20-D45 ...]``.
"""
import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness.analysis import diagnosis  # noqa: E402
from harness.analysis.diagnosis import jobs as diag_jobs  # noqa: E402
from harness.data.dataset import read_dataset  # noqa: E402
from harness.sim import simulator  # noqa: E402
from tests.independent.bounds import blind  # noqa: E402
from tests.independent.generator import RigConventions, make_dataset  # noqa: E402

EFFECT = {"filler_saturation": 1.0}


class StepCounter:
    """Wraps ``harness.sim.simulator.simulate`` (and the diagnosis's binding of it): counts runs x sample
    intervals integrated."""

    def __init__(self):
        self.intervals = 0
        self.calls = 0
        self.orig = simulator.simulate

    def __call__(self, runs, schedule=None):
        V = np.asarray(runs.V)
        dt = float(np.max(np.asarray(runs.dt, dtype=float)))
        if V.ndim == 2:
            n = V.shape[1]
        else:
            n = int(round(schedule.t_end / dt)) if schedule is not None else 0
        self.intervals += runs.n * n
        self.calls += 1
        return self.orig(runs, schedule) if schedule is not None else self.orig(runs)

    def __enter__(self):
        simulator.simulate = self
        if getattr(diag_jobs, "simulate", None) is self.orig:
            diag_jobs.simulate = self
        return self

    def __exit__(self, *exc):
        simulator.simulate = self.orig
        if getattr(diag_jobs, "simulate", None) is self:
            diag_jobs.simulate = self.orig


def _samples(ds) -> int:
    n = 0
    for s in ds.samples:
        for t in s.tests.values():
            n += t.time_s.size if hasattr(t, "time_s") else t.gap_mm.size
    return n


def _parse_sample(text: str) -> tuple:
    w, d = text.upper().lstrip("W").split("-D")
    return float(w), float(d)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", type=float, nargs="+", default=[1000.0, 2500.0, 5000.0, 10000.0], help="[Hz]")
    ap.add_argument("--samples", nargs="+", default=["W20-D45"], help="samples like W20-D45")
    a = ap.parse_args(argv)
    samples = [_parse_sample(s) for s in a.samples]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for rate in a.rates:
            out = Path(tmp) / f"r{rate:g}"
            make_dataset(out, RigConventions(sample_rate_hz=rate), EFFECT, seed=1, samples=samples)
            ds = read_dataset(out)
            ds = blind(ds)
            with StepCounter() as cnt:
                t0 = time.perf_counter()
                diag = diagnosis.diagnose(ds, diagnosis.DiagnoseSettings(workers=1))
                wall = time.perf_counter() - t0
            ov = diag.gain["overall_normalized_rmse"]
            rows.append((rate, _samples(ds), wall, cnt.intervals, cnt.calls, diag.verdict or diag.cause,
                         ov["before"], ov["after"]))
            print(f"  {rate:7.0f} Hz done: {wall:.1f} s, verdict {rows[-1][5]}", flush=True)
    r0 = rows[0]
    print(f"diagnosis cost vs sample rate ({len(samples)} samples {', '.join(a.samples)}, hidden {EFFECT}, "
          f"one worker; load average {os.getloadavg()[0]:.2f})")
    print(f"{'rate_Hz':>8} {'data_samples':>12} {'wall_s':>8} {'sim_intervals':>14} {'sim_calls':>9} "
          f"{'wall/sample rel.':>16} {'intervals/sample rel.':>21}  verdict (held-out RMSE before -> after)")
    for rate, n, wall, iv, calls, verdict, b, af in rows:
        print(f"{rate:8.0f} {n:12d} {wall:8.1f} {iv:14d} {calls:9d} {(wall / n) / (r0[2] / r0[1]):16.3f} "
              f"{(iv / n) / (r0[3] / r0[1]):21.3f}  {verdict} ({b:.3g} -> {af:.3g})")
    rn = rows[-1]
    print(f"ratio {rn[0]:g} Hz / {r0[0]:g} Hz: data x{rn[1] / r0[1]:.2f}, wall time x{rn[2] / r0[2]:.2f}, "
          f"simulated intervals x{rn[3] / r0[3]:.2f}")


if __name__ == "__main__":
    main()
