"""Summary of a deep property-profile run recorded with ``MPC_PROPS_RECORD`` (issue 20's measurements).

Run the deep profile with a record file, then summarize it::

    MPC_PROPS_RECORD=deep.jsonl nice pytest -m deep tests/independent/test_properties.py -n 2
    python benchmarks/deep_profile_report.py deep.jsonl

Prints: how many descriptions were analysed (unique, by kind), the ranges of the space they covered (sample
rates, samples, record lengths, noise multipliers), the wall time of each stage (read, conventions, identify,
diagnose) per dataset (median, 95th percentile, maximum; how many diagnoses took more than 60 s and 120 s),
the verdicts on clean data, and over the clean datasets (no hidden effect, every test present, no contact in
T3/T5; the coverage test's identify-only analyses count here too) the coverage of identify's 95 % intervals of R, L, Em, K1, K2, C, m (fraction holding the truth; target
90-98 %) with the mean and rms of z = (estimate - truth) / sd.

Hypothesis analyses some descriptions more than once while shrinking; each description counts once (its last
record).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from collections import Counter
from pathlib import Path

import numpy as np

KEYS = ("R_Ohm", "L_H", "Em_N_m_per_T2", "K1_N_per_m3", "K2_N_per_m", "C_N_s_per_m", "m_kg")
STAGES = ("read", "conventions", "identify", "diagnose")


def load(path: Path) -> list:
    """The records of ``path`` (JSON lines), one per description (the last one); the explicit examples and the
    shrunk failures of ``REGRESSIONS`` (``drawn`` false) are left out: the profile's draws only."""
    by_desc = {}
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as e:
            raise SystemExit(f"error: {path}, line {n}: not JSON ({e.msg})")
        if rec.get("drawn", True):
            by_desc[rec["desc"]] = rec
    return list(by_desc.values())


def _desc_fields(rec: dict) -> dict:
    """The RigDescription's fields of a record (its repr is valid Python: evaluated in a namespace holding
    only the class's constructor, which records its keyword arguments)."""
    return eval(rec["desc"], {"__builtins__": {}}, {"RigDescription": lambda **kw: kw})   # noqa: S307


def unique_rows(clean: list) -> list:
    """The interval rows of the clean records, each noise realization once. The generator seeds a sample's noise by
    (description seed, sample, test): descriptions with the same seed and sample share that noise (Hypothesis
    draws near-copies of its simplest examples, seed 0 and the smallest samples, with only a rate or a clock
    changed), and counting each would weigh one realization many times. The first row of each (seed, sample,
    parameter) counts."""
    seen, out = set(), []
    for r in clean:
        seed = _desc_fields(r).get("seed", 0)
        for row in r["intervals"]:
            k = (seed, row["sample"], row["key"])
            if k not in seen:
                seen.add(k)
                out.append(row)
    return out


def summary(recs: list) -> str:
    out = []
    kinds = Counter("effect" if r["effect"] else ("clean" if r["clean"] else "clean, incomplete or contact")
                    for r in recs)
    out.append(f"descriptions analysed: {len(recs)} ({', '.join(f'{v} {k}' for k, v in sorted(kinds.items()))})")
    f = [_desc_fields(r) for r in recs]
    rates = [x for d in f for x in d["rates_hz"]] + [d["sweep_rate_hz"] for d in f]
    noise = [x for d in f for x in d["noise"]]
    out.append(f"ranges covered: sample rates {min(rates):g}-{max(rates):g} Hz; samples per dataset "
               f"{min(len(d['samples']) for d in f)}-{max(len(d['samples']) for d in f)}; wt% "
               f"{min(s[0] for d in f for s in d['samples'])}-{max(s[0] for d in f for s in d['samples'])}; "
               f"D {min(s[1] for d in f for s in d['samples'])}-{max(s[1] for d in f for s in d['samples'])} mm; "
               f"records {min(d['record_s'] for d in f):g}-{max(d['record_s'] for d in f):g} s; noise x "
               f"{min(noise):g}-{max(noise):g}; coil radius {min(d['coil_radius_mm'] for d in f):g}-"
               f"{max(d['coil_radius_mm'] for d in f):g} mm; single-reading sweeps "
               f"{sum(d['sweep_average_s'] is None for d in f)}, tests absent in "
               f"{sum(bool(d['absent']) for d in f)}")
    out.append("")
    for field, what in (("stage_s", "wall time"), ("stage_cpu_s", "CPU time (the wall time on an idle core)")):
        have = [r for r in recs if field in r]
        if not have:
            continue
        out.append(f"{what} per dataset [s] (one process, one worker):")
        out.append(f"  {'stage':12s} {'n':>4s} {'median':>8s} {'p95':>8s} {'max':>8s}")
        for st in STAGES + ("total",):
            v = np.array([sum(r[field].values()) if st == "total" else r[field][st]
                          for r in have if st == "total" or st in r[field]])
            if v.size:
                out.append(f"  {st:12s} {v.size:4d} {np.median(v):8.1f} {np.percentile(v, 95):8.1f} {v.max():8.1f}")
        diag = [(r[field]["diagnose"], r) for r in have if "diagnose" in r[field]]
        out.append(f"  diagnoses over 60 s: {sum(t > 60 for t, _ in diag)}; over 120 s: "
                   f"{sum(t > 120 for t, _ in diag)}")
        if diag:
            t, r = max(diag, key=lambda x: x[0])
            out.append(f"  slowest diagnosis: {t:.1f} s: {r['desc']}")
    out.append("")
    errs = Counter(e.split(":")[0] + " at " + st for r in recs for st, e in r["errors"].items())
    out.append("refusals: " + (", ".join(f"{v} x {k}" for k, v in errs.most_common()) or "none"))
    clean = [r for r in recs if r["clean"]]
    diagnosed = [r for r in clean if r.get("diagnosed", True)]
    out.append(f"verdicts on {len(diagnosed)} diagnosed clean datasets: " + ", ".join(
        f"{v} x {k}" for k, v in Counter(r["verdict"] for r in diagnosed).most_common()) + (
        f"; {len(clean) - len(diagnosed)} more identified only (the coverage test)" if len(diagnosed) < len(clean)
        else ""))
    out.append("")
    rows = unique_rows(clean)
    n_sets = sum(bool(r["intervals"]) for r in clean)
    n_all = len({(r['desc'], row['sample']) for r in clean for row in r['intervals']})
    n_unique = len({(row["sample"], row["estimate"]) for row in rows if row["key"] == KEYS[0]})
    out.append(f"95 % intervals of identify (joint covariance of the seven parameters) over {n_sets} clean datasets, "
               f"{n_all} samples, {n_unique} of them distinct noise realizations (the rows counted):")
    out.append(f"  {'parameter':16s} {'n':>5s} {'coverage':>9s} {'mean z':>8s} {'rms z':>7s}")
    for key in KEYS:
        sel = [row for row in rows if row["key"] == key]
        if not sel:
            continue
        hit = np.mean([row["lo"] <= row["truth"] <= row["hi"] for row in sel])
        z = np.array([(row["estimate"] - row["truth"]) / row["sd"] for row in sel if row["sd"] > 0])
        out.append(f"  {key:16s} {len(sel):5d} {100 * hit:8.1f}% {np.mean(z):8.2f} {math.sqrt(np.mean(z ** 2)):7.2f}")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("record", type=Path, help="the JSON-lines file written with MPC_PROPS_RECORD")
    a = ap.parse_args(argv)
    if not a.record.is_file():
        print(f"error: {a.record}: no such file", file=sys.stderr)
        return 1
    recs = load(a.record)
    if not recs:
        print(f"error: {a.record}: no records", file=sys.stderr)
        return 1
    print(summary(recs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
