"""Robustness of the offset-free MPC on the EKF (harness.control.robustness): plants that differ from the model,
noisy and delayed measurements, against the full-state perfect-model MPC. Prints the Markdown table of
docs/guide/control.md ("Robustness") and writes it with the rows as JSON.

    python benchmarks/control_robustness.py [--fmu mpc_actuator.fmu] [--out robustness.json] [--plain]

--plain: the MPC on the EKF without disturbance model (not offset-free). About 50 closed-loop runs (2 s stroke,
1.8 s staircase each, 1 ms plant steps): a few minutes on 2 cores. The per-step times are wall clock on a shared
machine: see bench_mpc.py / bench_estimator_mpc.py for the timing benchmark.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from harness.control.robustness import markdown_table, run_robustness  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fmu", default=str(REPO / "mpc_actuator.fmu"))
    ap.add_argument("--out", default=None, help="JSON file for the rows (default: none)")
    ap.add_argument("--plain", action="store_true", help="EKF without the disturbance model")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = run_robustness(args.fmu, offset_free=not args.plain, progress=lambda s: print(s, file=sys.stderr, flush=True))
    print(markdown_table(rows))
    contacts = sum(r["contact_events"] for r in rows)
    print(f"\n{len(rows)} runs in {time.perf_counter() - t0:.0f} s (load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores); contact events in all runs: {contacts}")
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
