"""Run a benchmark script of another checkout (the pre-restructuring code) in a subprocess, for a side-by-side
comparison: ``--baseline-tree /work/wt-base`` of bench_identify.py and bench_diagnose.py.

The other checkout's own copy of the script runs (same workload and arguments it understands), with
PYTHONPATH and the working directory pointing at that checkout and the same Python interpreter; the
wall time is read from the line of its output that matches ``pattern``.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path


def run_baseline(tree, script: str, args: list, pattern: str) -> tuple[float, str]:
    """(wall time [s], full output) of ``tree/benchmarks/<script> <args>`` run in a subprocess."""
    tree = Path(tree).resolve()
    path = tree / "benchmarks" / script
    if not path.exists():
        raise SystemExit(f"--baseline-tree: {path} not found")
    env = dict(os.environ, PYTHONPATH=str(tree))
    proc = subprocess.run([sys.executable, str(path), *args], cwd=tree, env=env, capture_output=True, text=True)
    out = proc.stdout + proc.stderr
    if proc.returncode != 0:
        raise SystemExit(f"baseline benchmark failed ({proc.returncode}):\n{out}")
    m = re.search(pattern, out)
    if m is None:
        raise SystemExit(f"baseline benchmark: no line matching {pattern!r} in its output:\n{out}")
    return float(m.group(1)), out


def report(name: str, new_s: float, base_s: float, tree) -> None:
    """Print both wall times and their ratio."""
    print(f"{name}: this tree {new_s:.1f} s, baseline ({tree}) {base_s:.1f} s, "
          f"ratio this/baseline {new_s / base_s:.2f}")
