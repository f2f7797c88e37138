"""Does the diagnosis pay off in control? Measured honestly (issue 21, part 3).

For each effect of the catalogue: the virtual rig generates a dataset (three 45 mm samples, 10/20/30 wt%) with
that effect hidden at magnitude 1; ``diagnose`` reads it blind; the controllers (the PI controller FMU and the
MPC) are built once on the paper model *that diagnosis refitted* (``paper_refit``) and once on the extended model
*that diagnosis produced* (``extended_params.json``), never on true parameters; both drive the same plant: the
actuator FMU with the sample's true parameters and the hidden effect. Printed per effect: the diagnosis's verdict,
and for PI and MPC the stroke-tracking RMSE [um] with each model and the ratio paper / extended (> 1: the
diagnosis pays off).

Usage: ``python benchmarks/control_payoff.py [--effects coil_heating ...] [--sample W20-D45] [--stroke-mm 1]
[--workers 2]``. Minutes per effect (generation, diagnosis, 8 closed-loop runs); run it with ``nice``.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmu_src.specs import EFFECTS  # noqa: E402
from harness import jobs  # noqa: E402
from harness.control.study import StudySettings, run_study  # noqa: E402
from harness.data.dataset import read_dataset  # noqa: E402
from harness.data.paramsjson import params_from_json  # noqa: E402
from harness.pipeline import DatasetSettings, JobSettings, fmu_path  # noqa: E402

SAMPLES = ((10.0, 45.0), (20.0, 45.0), (30.0, 45.0))
CONTROLLER_FMU = Path(__file__).resolve().parents[1] / "mpc_controller.fmu"


def payoff(effect: str, sample: str, stroke_mm: float, workers: int, tmp: Path) -> dict:
    job = JobSettings(workers=workers, progress=False)
    ds_dir = tmp / f"ds-{effect}"
    jobs.generate(ds_dir, DatasetSettings(seed=3, samples=SAMPLES, hidden_effects=((effect, 1.0),)), job=job)
    t0 = time.perf_counter()
    diag, _ = jobs.diagnose(ds_dir, tmp / f"diag-{effect}", job=job)
    t_diag = time.perf_counter() - t0
    dj = json.loads((tmp / f"diag-{effect}" / "diagnosis.json").read_text())
    paper = params_from_json(dj["parameters"]["paper_refit"][sample], f"diagnosis.json paper_refit {sample}")
    ext = jobs.load_params_file(tmp / f"diag-{effect}" / "extended_params.json")[sample]
    ds = read_dataset(ds_dir)
    true = jobs.true_params(ds)[sample]
    true_eff = jobs.true_params(ds, with_effects=True)[sample]
    effect_params = {n: float(getattr(true_eff, n)) for n in EFFECTS[effect].params}
    r0 = true.r0
    s = StudySettings(actuator_fmu=str(fmu_path()), controller_fmu=str(CONTROLLER_FMU), base=true,
                      effect=effect, effect_params=effect_params, paper_model=paper.with_(r0=r0),
                      extended_params=ext.with_(r0=r0), stroke_m=stroke_mm / 1000.0,
                      sample=f"{sample} (true parameters; models from the blind diagnosis)")
    res = run_study(s)
    rmse = {(r["model"], r["controller"]): r["rmse_m"] for r in res.rows
            if r["plant"] != "clean" and r["profile"] == "stroke"}
    return {"effect": effect, "verdict": diag.verdict, "diagnose_s": t_diag, "rmse_m": rmse}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effects", nargs="+", default=list(EFFECTS), choices=list(EFFECTS))
    ap.add_argument("--sample", default="W20-D45")
    ap.add_argument("--stroke-mm", type=float, default=1.0)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    print(f"{'effect':20s} {'diagnosis':28s} {'PI paper':>9s} {'PI ext':>9s} {'ratio':>6s} "
          f"{'MPC paper':>9s} {'MPC ext':>9s} {'ratio':>6s}   (stroke RMSE [um], sample {a.sample}, "
          f"{a.stroke_mm:g} mm)")
    with tempfile.TemporaryDirectory() as d:
        for e in a.effects:
            r = payoff(e, a.sample, a.stroke_mm, a.workers, Path(d))
            m = r["rmse_m"]
            cells = []
            for ctl in ("PI", "MPC"):
                p, x = m.get(("paper", ctl), float("nan")), m.get(("extended", ctl), float("nan"))
                cells += [f"{1e6 * p:9.1f}", f"{1e6 * x:9.1f}", f"{p / x:6.2f}"]
            print(f"{e:20s} {r['verdict'][:28]:28s} {' '.join(cells)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
