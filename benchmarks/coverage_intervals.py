"""Coverage of identify's 95 % intervals (``interval_95``, from the joint covariance ``covariance_7``) on clean data.

Generates clean datasets with the independent generator (``tests/independent/generator.py``: its own physics
and solver), dataset i with the rig conventions ``CONVENTIONS[i % len]`` (the clean members of the matrix,
reduced like the fast member: two T6 periods, a 2 mm sweep grid, records cut to 2.25 s after the
pre-trigger, the three 45 mm samples) and noise seed i; identifies each blinded (the truth removed from the
manifest, as ``tests/independent/bounds.py`` does) with a small NSGA-II (24 x 15: the least-squares C, m start
at the front's best model and do not depend on the front's quality); prints for each of R, L, Em, K1, K2, C, m
the fraction of samples whose 95 % interval holds the truth (target 90-98 %), the mean and rms of
z = (estimate - truth) / sd, and for C and m also the coverage of the profile-likelihood intervals with the
analytic parameters held (``least_squares``: what the intervals were before the propagation).

Usage: ``python benchmarks/coverage_intervals.py [--n 60] [--budget-s 900]`` (stops starting datasets once
the budget is spent). One process; run it with ``nice``.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness.analysis.identification.identify import identify_dataset  # noqa: E402
from harness.analysis.identification.settings import IdentifySettings  # noqa: E402
from harness.data.dataset import read_dataset  # noqa: E402
from tests.independent.bounds import blind  # noqa: E402
from tests.independent.generator import FAST_MATRIX, MATRIX, make_dataset  # noqa: E402

_FAST = FAST_MATRIX["fast-clean-400Hz-single"]
NAMES = ("fast-clean-400Hz-single", "clean-500Hz-single", "clean-250Hz-phase-clock12", "clean-200Hz-noisy5x",
         "clean-nocoil-mixed-noise", "clean-ours", "clean-2kHz-quiet-longpre")
KEYS = ("R_Ohm", "L_H", "Em_N_m_per_T2", "K1_N_per_m3", "K2_N_per_m", "C_N_s_per_m", "m_kg")


def reduced(name: str):
    """The conventions of matrix member ``name``, reduced like the fast member."""
    c = {**MATRIX, **FAST_MATRIX}[name].conventions
    if name in FAST_MATRIX:
        return c
    fast = _FAST.conventions
    return dataclasses.replace(c, t6_periods=2, sweep_gaps_mm=fast.sweep_gaps_mm,
                               record_s=min(c.record_s, c.pre_trigger_s + 2.25))


def run(n: int, budget_s: float, settings: IdentifySettings) -> dict:
    rows = []                    # (name, sid, key, estimate, sd, lo, hi, truth)
    prof = []                    # (key, lo, hi, truth): profile intervals with the analytic parameters held
    t0 = time.perf_counter()
    done = 0
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(n):
            if time.perf_counter() - t0 > budget_s:
                break
            name = NAMES[i % len(NAMES)]
            ds = read_dataset(make_dataset(Path(tmp) / f"d{i}", reduced(name), seed=i, samples=_FAST.samples,
                                           description=f"coverage study, {name}, seed {i}"))
            truth = ds.rig["independent_truth"]
            res = identify_dataset(blind(ds), settings, progress=False, workers=1)
            for sid, r in res.items():
                if r.covariance_7 is None:
                    print(f"  {name} seed {i} {sid}: no covariance ({r.least_squares.get('error')})")
                    continue
                cov = np.asarray(r.covariance_7["matrix"])
                sd = np.sqrt(np.diag(cov))
                est = [float(getattr(r.params, n)) for n in ("R", "L", "Em", "K1", "K2")]
                est += [r.least_squares["C_N_s_per_m"], r.least_squares["m_kg"]]
                for k, key in enumerate(r.covariance_7["parameters"]):
                    lo, hi = r.interval_95[key]
                    rows.append((name, sid, key, est[k], sd[k], lo, hi, float(truth[sid][key])))
                for key, ik in (("C_N_s_per_m", "C_interval_95_N_s_per_m"), ("m_kg", "m_interval_95_kg")):
                    lo, hi = r.least_squares[ik]
                    prof.append((key, lo, hi, float(truth[sid][key])))
            done += 1
            print(f"  dataset {i} ({name}) done, {time.perf_counter() - t0:.0f} s", flush=True)
    return {"rows": rows, "profile": prof, "datasets": done, "time_s": time.perf_counter() - t0}


def table(out: dict) -> str:
    rows, prof = out["rows"], out["profile"]
    n_samples = len({(r[0], r[1], i) for i, r in enumerate(rows) if r[2] == "R_Ohm"})
    lines = [f"{out['datasets']} datasets, {n_samples} samples, {out['time_s']:.0f} s",
             f"{'parameter':16s} {'coverage_95':>11s} {'mean z':>8s} {'rms z':>7s} {'profile-only':>13s}"]
    for key in KEYS:
        sel = [r for r in rows if r[2] == key]
        if not sel:
            continue
        cov = np.mean([lo <= t <= hi for *_, lo, hi, t in sel])
        z = np.array([(e - t) / s for _, _, _, e, s, _, _, t in sel if s > 0])
        p = [lo <= t <= hi for k, lo, hi, t in prof if k == key]
        ptxt = f"{100 * np.mean(p):12.1f}%" if p else " " * 13
        lines.append(f"{key:16s} {100 * cov:10.1f}% {z.mean():8.2f} {math.sqrt(np.mean(z ** 2)):7.2f} {ptxt}")
    by = {}
    for name, _, key, e, s, lo, hi, t in rows:
        if key in ("C_N_s_per_m", "m_kg"):
            by.setdefault((name, key), []).append(lo <= t <= hi)
    lines.append("C, m coverage by conventions: " + "; ".join(
        f"{name} {key.split('_')[0]} {sum(v)}/{len(v)}" for (name, key), v in sorted(by.items())))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=60, help="datasets at most (3 samples each)")
    ap.add_argument("--budget-s", type=float, default=900.0, help="no dataset is started after this time [s]")
    a = ap.parse_args(argv)
    out = run(a.n, a.budget_s, IdentifySettings(pop_size=24, n_gen=15))
    print(table(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
