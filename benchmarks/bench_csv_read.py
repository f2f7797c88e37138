"""Benchmark: reading one large test CSV, the whole-file reader against the streaming one (issue 24, item 7).

    python benchmarks/bench_csv_read.py [--rows 5000000] [--old-rev main] [--tracemalloc] [--keep DIR]

1. Writes a T3 CSV of ``--rows`` rows (5 million: about 200 MB; time_s,voltage_V,current_A,displacement_mm
   with a comment line) in a temporary folder (not timed).
2. Reads it with each reader in a fresh subprocess and prints its wall time and peak memory: the growth
   of the process's peak resident set (``resource.getrusage(...).ru_maxrss`` after reading minus before;
   Linux, so 1 KiB units) and, with ``--tracemalloc``, the tracemalloc peak (which slows the old
   reader several times). Both are given as multiples of the parsed float64 arrays.
   * old: ``harness/data/csvfile.py`` of git revision ``--old-rev`` (``git show REV:...``, imported as a
     module; tests/data/csv_reference.py when git cannot give it): ``parse_csv(decode_text(raw))`` on the
     bytes read whole, as dataset.py did;
   * new: ``harness.data.csvfile.read_csv(path)``.
3. Checks that both give the same arrays (a checksum of their bytes) and prints the ratios old/new.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

CHILD = textwrap.dedent("""
    import hashlib, importlib.util, json, resource, sys, time, tracemalloc
    which, path, old_module, trace = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4] == "1"
    import numpy as np
    if which == "old":
        spec = importlib.util.spec_from_file_location("old_csvfile", old_module)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        def read():
            with open(path, "rb") as fh:
                raw = fh.read()
            return mod.parse_csv(mod.decode_text(raw, path), "T3", path)
    else:
        from harness.data.csvfile import read_csv
        def read():
            return read_csv(path, "T3")
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    if trace:
        tracemalloc.start()
    t0 = time.perf_counter()
    out = read()
    wall = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] if trace else None
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    h = hashlib.sha256()
    for k in sorted(out):
        h.update(k.encode()); h.update(np.ascontiguousarray(out[k]).tobytes())
    print(json.dumps(dict(wall=wall, rss_kib=rss1 - rss0, tracemalloc=peak, rows=len(out["time_s"]),
                          nbytes=sum(v.nbytes for v in out.values()), sha=h.hexdigest())))
""")


def write_csv(path: Path, rows: int) -> None:
    rng = np.random.default_rng(0)
    block = 500_000
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write("# benchmark data (synthetic), T3\ntime_s,voltage_V,current_A,displacement_mm\n")
        for i0 in range(0, rows, block):
            n = min(block, rows - i0)
            t = (i0 + np.arange(n)) * 1e-4
            v = 6.0 + 0.01 * rng.standard_normal(n)
            i = 0.3 * (1 - np.exp(-t)) + 1e-3 * rng.standard_normal(n)
            x = 2.5 * (1 - np.exp(-t / 2)) + 1e-3 * rng.standard_normal(n)
            np.savetxt(fh, np.column_stack([t, v, i, x]), delimiter=",", fmt=["%.10g", "%.8g", "%.8g", "%.8g"])


def old_module(rev: str, tmp: Path) -> Path:
    dst = tmp / "old_csvfile.py"
    try:
        src = subprocess.run(["git", "show", f"{rev}:harness/data/csvfile.py"], cwd=ROOT, check=True,
                             capture_output=True, text=True).stdout
        print(f"old reader: harness/data/csvfile.py of git revision {rev}")
    except (OSError, subprocess.CalledProcessError):
        src = (ROOT / "tests" / "data" / "csv_reference.py").read_text()
        print("old reader: tests/data/csv_reference.py (git show failed)")
    dst.write_text(src)
    return dst


def run(which: str, path: Path, module: Path, trace: bool) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-c", CHILD, which, str(path), str(module), "1" if trace else "0"],
                       env=env, capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=5_000_000)
    ap.add_argument("--old-rev", default="main")
    ap.add_argument("--tracemalloc", action="store_true", help="also the tracemalloc peak (slows the old reader)")
    ap.add_argument("--keep", type=Path, help="write the CSV into this folder (kept) instead of a temporary one")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        folder = args.keep or tmp
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / "T3.csv"
        write_csv(path, args.rows)
        size = path.stat().st_size
        print(f"file: {args.rows} rows, {size / 1e6:.0f} MB ({path})")
        module = old_module(args.old_rev, tmp)
        res = {w: run(w, path, module, args.tracemalloc) for w in ("old", "new")}
    arrays = res["new"]["nbytes"]
    print(f"parsed arrays: {arrays / 1e6:.0f} MB (4 columns float64)")
    print(f"{'reader':<8}{'wall s':>10}{'peak RSS growth MB':>22}{'x arrays':>10}"
          + (f"{'tracemalloc MB':>17}{'x arrays':>10}" if args.tracemalloc else ""))
    for w in ("old", "new"):
        r = res[w]
        line = f"{w:<8}{r['wall']:>10.2f}{r['rss_kib'] * 1024 / 1e6:>22.0f}{r['rss_kib'] * 1024 / arrays:>10.2f}"
        if args.tracemalloc:
            line += f"{r['tracemalloc'] / 1e6:>17.0f}{r['tracemalloc'] / arrays:>10.2f}"
        print(line)
    o, n = res["old"], res["new"]
    print(f"old/new: wall {o['wall'] / n['wall']:.1f}x, peak RSS growth {o['rss_kib'] / max(n['rss_kib'], 1):.1f}x"
          + (f", tracemalloc peak {o['tracemalloc'] / n['tracemalloc']:.1f}x" if args.tracemalloc else ""))
    same = o["sha"] == n["sha"] and o["rows"] == n["rows"]
    print(f"same arrays: {'yes' if same else 'NO'} ({n['rows']} rows)")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
