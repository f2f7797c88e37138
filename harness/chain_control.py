"""The control step of the chain (:mod:`harness.chain`): the closed-loop study (``harness.control.study``) on one
of the user's samples. The plant is the sample's best model (the diagnosis's extended model: the identified
paper parameters plus the effect parameters the diagnosis fitted to that sample; the paper model when the
diagnosis named no effect); the controllers are built once on the paper model and once on the extended model.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from fmu_src.specs import active_effects
from harness import jobs, jobs_control
from harness.data.dataset import Dataset
from harness.pipeline import PipelineError
from harness.report.run_md import StepRecord

#: build the controller FMU with ``python build_fmu.py --controller``
CONTROLLER_FMU = Path(__file__).resolve().parents[1] / "mpc_controller.fmu"


def middle_sample(results: dict) -> str:
    """The identified sample nearest the middle of the data: the smallest distance to the centre of the
    (filler fraction, diameter) ranges, each range scaled to 1 (ties: the first id in order)."""
    ids = sorted(results)
    w = np.array([results[s].wt_pct for s in ids], dtype=float)
    d = np.array([results[s].diameter_mm for s in ids], dtype=float)

    def unit(v):
        span = float(np.ptp(v))
        return (v - v.min()) / span if span > 0 else np.zeros_like(v)
    dist = np.hypot(unit(w) - 0.5, unit(d) - 0.5)
    return ids[int(np.argmin(dist))]


def sample_gap_mm(ds: Dataset, sid: str) -> float:
    """The gap [mm] of the sample's T5 (where the identification took place), else the build default."""
    s = next((x for x in ds.samples if x.id == sid), None)
    t = s.tests.get("T5") if s is not None else None
    g = getattr(t, "gap_mm", None)
    return float(g) if isinstance(g, (int, float)) and math.isfinite(g) and g > 0 else jobs.BuildSettings().gap_mm


def control_step(st) -> StepRecord:
    """The control study on ``st.settings.control['sample']`` (default: :func:`middle_sample`), as
    ``mpc-actuator control --params extended_params.json --sample ID`` runs it (``harness.jobs_control.control_settings``:
    the plant and the extended model are the sample with the effects the diagnosis fitted to it, the paper model
    the same sample without them; without a diagnosis (or without effects) the plant is the identified paper
    model and only that model is studied."""
    from harness.control.mpc import MpcSettings
    from harness.control.study import StudySettings, run_study
    from harness.report.control_md import write_control_report
    c = dict(st.settings.control)
    sid = c.get("sample") or middle_sample(st.results)
    if sid not in st.results:
        raise PipelineError(f"[control] sample {sid!r} is not an identified sample (identified: "
                            f"{', '.join(sorted(st.results))})")
    if not CONTROLLER_FMU.is_file():
        raise PipelineError(f"controller FMU {CONTROLLER_FMU} not found; build it with `python build_fmu.py --controller`")
    gap_m = sample_gap_mm(st.ds, sid) / 1000.0
    stroke_m = float(c.get("stroke_mm", min(1.0, 0.25 * gap_m * 1e3))) / 1000.0
    mpc = MpcSettings(V_max_V=float(c.get("v_max", 30.0)), margin_m=float(c.get("margin_mm", 0.5)) / 1000.0)
    pf = st.params_files.get("extended")
    params = jobs.load_params_file(pf) if pf is not None else {}
    if sid not in params:
        pf = st.params_files["identified"]
        params = jobs.load_params_file(pf)
    base = params[sid].with_(r0=gap_m)
    settings = StudySettings(actuator_fmu=str(st.fmu), controller_fmu=str(CONTROLLER_FMU), base=base, effect=None,
                             stroke_m=stroke_m, freq_Hz=float(c.get("freq_hz", 2.0)), mpc=mpc)
    settings = jobs_control.control_settings(settings, params_file=pf, sample=sid)
    settings = replace(settings, base=settings.base.with_(r0=gap_m))
    ext = active_effects(base)
    res = run_study(settings)
    written = write_control_report(st.out / "control", res, settings)
    what = (f"plant = {sid}'s extended model ({', '.join(sorted(ext))} from the diagnosis)" if ext else
            f"plant = {sid}'s paper model ({'the diagnosis named no effect' if pf.name.startswith('extended') else 'no diagnosis'})")
    return StepRecord("control", files=written, summary=f"control study on {sid}: {what}",
                      rows=[{**r, "sample": sid} for r in res.rows])
