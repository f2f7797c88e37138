"""Compare the numbers of two output folders of ``mpc-actuator run`` (e.g. before and after a change).

Walks the JSON files named on the command line (default: identification/identification.json,
identification/generalization.json, diagnosis/diagnosis.json) in both folders, pairs their numbers by
path (``diagnosis.json:gain.overall_normalized_rmse.after``), and prints every number whose relative
difference exceeds ``--rtol`` (default 1e-9), every string or boolean that differs, and every path found
in one folder only. Wall-time entries (keys with ``timing`` or ``wall``) are skipped.

    python benchmarks/compare_outputs.py /work/baseline_out out
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

DEFAULT_FILES = ("identification/identification.json", "identification/generalization.json",
                 "diagnosis/diagnosis.json")
SKIP = ("timing", "wall")


def flatten(obj, prefix: str = "") -> dict:
    """{path: leaf} of a JSON value (lists indexed by position)."""
    if isinstance(obj, dict):
        items = obj.items()
    elif isinstance(obj, list):
        items = ((str(i), v) for i, v in enumerate(obj))
    else:
        return {prefix: obj}
    out = {}
    for k, v in items:
        if any(s in str(k) for s in SKIP):
            continue
        out.update(flatten(v, f"{prefix}.{k}" if prefix else str(k)))
    return out


def rel_diff(a: float, b: float) -> float:
    """|a - b| / max(|a|, |b|) (0 for equal values, NaN pairs included)."""
    if a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)):
        return 0.0
    return abs(a - b) / max(abs(a), abs(b))


def compare(old: dict, new: dict, rtol: float) -> list:
    """Differences of two flattened files: [(path, old, new, relative difference or None)]."""
    diffs = []
    for path in sorted(set(old) | set(new)):
        if path not in old or path not in new:
            diffs.append((path, old.get(path, "<absent>"), new.get(path, "<absent>"), None))
            continue
        a, b = old[path], new[path]
        num = (int, float)
        if isinstance(a, num) and isinstance(b, num) and not isinstance(a, bool) and not isinstance(b, bool):
            d = rel_diff(float(a), float(b))
            if not d <= rtol:
                diffs.append((path, a, b, d))
        elif a != b:
            diffs.append((path, a, b, None))
    return diffs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("old", type=Path, help="output folder before")
    ap.add_argument("new", type=Path, help="output folder after")
    ap.add_argument("--rtol", type=float, default=1e-9, help="relative difference reported (default 1e-9)")
    ap.add_argument("--files", nargs="*", default=list(DEFAULT_FILES), help="JSON files inside the folders")
    a = ap.parse_args(argv)
    total = 0
    for name in a.files:
        old = flatten(json.loads((a.old / name).read_text()))
        new = flatten(json.loads((a.new / name).read_text()))
        diffs = compare(old, new, a.rtol)
        total += len(diffs)
        print(f"{name}: {len(old)} entries, {len(diffs)} differ beyond rtol {a.rtol:g}")
        for path, x, y, d in diffs:
            rel = f"  rel {d:.2e}" if d is not None else ""
            print(f"  {path}: {x!r} -> {y!r}{rel}")
    return 1 if total else 0


if __name__ == "__main__":
    raise SystemExit(main())
