"""Wall time of `mpc-actuator diagnose` on three kinds of dataset, this tree and another checkout side by side.

The datasets (made once, by this tree, into a temporary folder):

* ``default``: the main job's default dataset (the virtual rig, the paper's 11 samples, 1 kHz, the default
  hidden effect ``harness.pipeline.DEFAULT_HIDDEN_EFFECT``, seed 0), written by ``mpc-actuator generate``;
* ``500Hz``: the dataset attached to the bug report ``../shared/bug-reports/clean-500hz-11-samples`` (another
  rig, 500 Hz, 11 samples, no hidden effect; its reduced copy ``tests/fixtures/clean-500hz-3-samples`` when
  the shared folder is not there);
* ``5kHz``: the independent generator (``tests/independent``: its own physics and solve_ivp) at 5 kHz, five
  samples, the step 0.4 periods after a sample, the clock at 1.7 s, no hidden effect (blinded like
  ``100Hz-creep``);
* ``100Hz-creep`` (not in the default list: ``--datasets 100Hz-creep``, nor the next two): the independent
  generator's session-17 deep case ``tests.independent.test_properties.CREEP_FAST_LAG_100HZ`` (a
  two-time-constant creep at 100 Hz, four samples), whose discovery once drove a lag to 0.1 ms (166 CPU-s);
* ``1539Hz-tanh`` (not in the default list): the session-19 deep case
  ``tests.independent.test_properties.SATURATION_TANH_1539HZ`` (a tanh filler saturation at 1539 Hz, four samples,
  4 s records), whose 45 CPU-s fit batches once ran its diagnosis to 123 CPU-s against a 75 CPU-s budget;
* ``mixed-rates-tanh`` (not in the default list): the session-20 deep case
  ``tests.independent.test_properties.SATURATION_TANH_MIXED_RATES`` (a tanh saturation, rates 100 Hz-10 kHz),
  122.9 CPU-s with one worker.

The generated datasets are blinded: the generator's truth (``rig.independent_*``) is removed from their
manifests on disk, as ``tests.independent.bounds.blind`` removes it from a read Dataset.

Each diagnosis runs as the command line does, in a subprocess (``python -m harness.cli diagnose DS --out ...
--quiet``, two workers) with the working directory and PYTHONPATH at the tree under test, one after the other
(never two at once); the wall time includes the interpreter's start. Beside it, the CPU time of the command and
its workers (``getrusage`` of the waited-for children: user + system), which the machine's load does not
inflate; the fits' budget (``fit_budget_s``) counts CPU time too (``harness.analysis.core.cpu_clock``). A run that fails prints its ``error:``
line instead of a time. Run from the repository root after ``make fmu``::

    python benchmarks/bench_diagnose_datasets.py --baseline-tree /work/wt-base
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

BUG_REPORT = ROOT.parent / "shared" / "bug-reports" / "clean-500hz-11-samples"
FIXTURE = ROOT / "tests" / "fixtures" / "clean-500hz-3-samples"


def _blinded(folder: Path) -> Path:
    """``folder`` with the generator's truth (``rig.independent_*``) removed from its manifest on disk, as
    ``tests.independent.bounds.blind`` removes it from a read Dataset: the command line sees what a user's has."""
    from tests.independent.bounds import without_truth
    manifest = folder / "manifest.json"
    m = json.loads(manifest.read_text())
    m["rig"] = without_truth(m["rig"])
    manifest.write_text(json.dumps(m, indent=1))
    return folder


def _default(tmp: Path) -> Path:
    from harness.pipeline import DEFAULT_HIDDEN_EFFECT
    effect = [a for k, v in DEFAULT_HIDDEN_EFFECT.items() for a in ("--effect", f"{k}={v:g}")]
    subprocess.run([sys.executable, "-m", "harness.cli", "generate", "--out", str(tmp / "default"), "--quiet",
                    "--seed", "0", *effect], cwd=ROOT, check=True)
    return tmp / "default"


def _5khz(tmp: Path) -> Path:
    from tests.independent.generator import RigConventions, make_dataset
    conv = RigConventions(sample_rate_hz=5000.0, step_phase=0.4, clock_start_s=1.7, record_s=3.0,
                          sweep_average_s=0.2, sweep_hold_s=1.0)
    return _blinded(make_dataset(tmp / "5kHz", conv, samples=((10, 45), (20, 45), (30, 45), (20, 30), (20, 60)),
                                 description="SYNTHETIC, independent generator, 5 kHz, benchmark"))


def _deep_case(name: str):
    def make(tmp: Path) -> Path:
        from tests.independent import test_properties
        from tests.independent.space import make_from_description
        return _blinded(make_from_description(tmp / name, getattr(test_properties, DEEP_CASES[name])))
    return make


#: benchmark datasets from deep-profile fixtures (tests.independent.test_properties): name -> fixture
DEEP_CASES = {"100Hz-creep": "CREEP_FAST_LAG_100HZ", "1539Hz-tanh": "SATURATION_TANH_1539HZ",
              "mixed-rates-tanh": "SATURATION_TANH_MIXED_RATES"}
#: name -> maker(tmp folder) -> dataset folder (made by this tree, only when asked for)
MAKERS = {"default": _default, "500Hz": lambda tmp: BUG_REPORT if BUG_REPORT.is_dir() else FIXTURE, "5kHz": _5khz,
          **{name: _deep_case(name) for name in DEEP_CASES}}


def make_datasets(tmp: Path, names=tuple(MAKERS)) -> dict:
    """{name: dataset folder} of the datasets ``names``, made by this tree."""
    return {name: MAKERS[name](tmp) for name in names}


def _children_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def diagnose_wall(tree: Path, ds: Path, out: Path) -> tuple:
    """(wall time [s], CPU time [s] of the command and its workers, the command's summary or error line) of one
    diagnosis with the code of ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    c0 = _children_cpu_s()
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "harness.cli", "diagnose", str(ds), "--out", str(out), "--quiet"],
                       cwd=tree, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    cpu = _children_cpu_s() - c0
    lines = (p.stdout + p.stderr).strip().splitlines()
    if p.returncode != 0:
        return None, None, next((ln for ln in lines if ln.startswith("error")), lines[-1] if lines else "failed")
    return wall, cpu, next((ln.strip() for ln in lines if "cause =" in ln), "")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline-tree", help="checkout of the code to compare with (e.g. the previous main)")
    ap.add_argument("--datasets", nargs="+", default=["default", "500Hz", "5kHz"], choices=sorted(MAKERS))
    a = ap.parse_args(argv)
    trees = [("this tree", ROOT)] + ([("baseline", Path(a.baseline_tree).resolve())] if a.baseline_tree else [])
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        data = make_datasets(tmp, a.datasets)
        print(f"load average before: {os.getloadavg()[0]:.2f} (2 workers per diagnosis, one diagnosis at a time)")
        rows = []
        for name in a.datasets:
            res = {}
            for label, tree in trees:
                res[label] = diagnose_wall(tree, data[name], tmp / f"out-{name}-{label.replace(' ', '-')}")
                wall, cpu, line = res[label]
                print(f"  {name:8s} {label:10s}: " + (f"{wall:6.1f} s wall, {cpu:6.1f} s CPU  {line}"
                                                      if wall is not None else f"FAILED  {line}"))
            rows.append((name, res))
        print(f"load average after: {os.getloadavg()[0]:.2f}")
        print("\n| dataset | " + " | ".join(f"{lbl} wall (CPU)" for lbl, _ in trees)
              + (" | ratio wall | ratio CPU |" if len(trees) > 1 else " |"))
        print("|---|" + "---|" * len(trees) + ("---|---|" if len(trees) > 1 else ""))
        for name, res in rows:
            cells = [f"{res[lbl][0]:.1f} s ({res[lbl][1]:.1f} s)" if res[lbl][0] is not None else "fails"
                     for lbl, _ in trees]
            ratio = ""
            if len(trees) > 1:
                (w0, c0, _), (w1, c1, _) = res["this tree"], res["baseline"]
                ratio = (f" {w0 / w1:.2f} | {c0 / c1:.2f} |" if (w0 and w1) else " - | - |")
            print(f"| {name} | " + " | ".join(cells) + " |" + ratio)


if __name__ == "__main__":
    main()
