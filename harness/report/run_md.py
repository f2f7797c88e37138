"""``report.md`` of the chain (``mpc-actuator run DATASET``, :mod:`harness.chain`): one report a researcher reads
top to bottom (what was measured; the model and its accuracy; what it gets wrong and why, and the extended
model's gain; the FMUs; the parameters' uncertainty; what it means for control and for design), then the step
times and an index of every figure and table written.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["StepRecord", "write_run_report"]

#: the report's section of each step
TITLES = {"check": "What was measured", "identify": "The model and its accuracy",
          "diagnose": "What the model gets wrong, and why", "fmus": "FMUs of every sample",
          "uncertainty": "Parameter uncertainty and prediction bands", "control": "What it means for control",
          "design": "Design advice"}


@dataclass
class StepRecord:
    """What one step of the chain did: its name, the files it wrote, a summary (first line: the terminal's),
    table rows (FMUs, control runs), why it was skipped (None: it ran) and its wall time [s]."""
    step: str
    files: list = field(default_factory=list)
    summary: str = ""
    rows: list = field(default_factory=list)
    skipped: str | None = None
    wall_s: float | None = None
    failed: str | None = None


def _rel(out: Path, p) -> str:
    try:
        return str(Path(p).relative_to(out))
    except ValueError:
        return str(p)


def _include(out: Path, rel: str, title: str) -> list:
    p = out / rel
    if not p.is_file():
        return []
    body = [ln for ln in p.read_text(encoding="utf-8").splitlines() if not ln.startswith("# ")]
    return [f"**{title}** ([{rel}]({rel})):", "", *body, ""]


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}" if math.isfinite(v) else "n/a"
    return str(v)


def _table(rows: list, cols: list) -> list:
    if not rows:
        return []
    return ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols),
            *("| " + " | ".join(_fmt(r.get(c, "")) for c in cols) + " |" for r in rows), ""]


_PARAM_COLS = (("R", "R_Ohm"), ("L", "L_H"), ("Em", "Em_N_m_per_T2"), ("K1", "K1_N_per_m3"), ("K2", "K2_N_per_m"),
               ("C", "C_N_s_per_m"), ("m", "m_kg"))


def _section_identify(out: Path, results: dict | None) -> list:
    md = ["Parameters identified per sample (paper section 3: R, L, Em, K1, K2 analytic; C, m by least squares "
          "on T3/T5 with their joint covariance), validated on T1-T8 through the FMU (Tables 3 and 4: errors "
          "of the simulation against the data), and predicted for the samples declared unseen from the "
          "surfaces over filler fraction and diameter (Table 5).", ""]
    rows = [{"sample": sid, "wt_pct": r.wt_pct, "diameter_mm": r.diameter_mm,
             **{key: float(getattr(r.params, name)) for name, key in _PARAM_COLS}}
            for sid, r in sorted((results or {}).items())]
    if rows:
        md += ["**Identified parameters** (SI; [identification/identification.json]"
               "(identification/identification.json) also holds their covariance and 95 % intervals):", "",
               *_table(rows, ["sample", "wt_pct", "diameter_mm", *(k for _, k in _PARAM_COLS)])]
    for rel, title in (("identification/validation_table3.md", "Table 3"),
                       ("identification/validation_table4.md", "Table 4"),
                       ("identification/validation_table5.md", "Table 5 (unseen samples)")):
        md += _include(out, rel, title)
    return md


def _section_diagnose(out: Path, diag) -> list:
    md = []
    if diag is not None:
        ov = (diag.gain or {}).get("overall_normalized_rmse", {})
        md += [f"Verdict (blind: the dataset's manifest is not read for effects): **{diag.verdict}**; cause: "
               f"**{diag.cause}**.", ""]
        if isinstance(ov, dict) and "before" in ov:
            md += [f"Held-out RMSE in sensor noise floors (tests and samples the fit did not see): paper model "
                   f"{_fmt(ov['before'])} -> extended model {_fmt(ov.get('after', float('nan')))}.", ""]
    md += [f"The evidence, the candidates' scores and the residual figures: [diagnosis/diagnosis.md]"
           f"(diagnosis/diagnosis.md); the extended model's parameters: "
           f"[diagnosis/extended_params.json](diagnosis/extended_params.json).", ""]
    return md


def _section_rows(rec: StepRecord) -> list:
    if rec.step == "fmus":
        return ["Each FMU has its sample's parameters baked in as start values (FMI 2.0 co-simulation; "
                "`fmpy simulate FILE` runs it); paper model from the identification or the surfaces, extended "
                "model from the diagnosis.", "",
                *_table(rec.rows, ["sample", "model", "parameters", "gap_mm", "file", "fmpy_validate"])]
    if rec.step == "control":
        cols = ["sample", "plant", "model", "controller", "profile", "rmse_m", "max_abs_error_m", "max_x_m"]
        rows = [r for r in rec.rows if r.get("profile") == "stroke"]
        return ["Stroke tracking (sine reference) by the PI controller FMU and the MPC, each built on the "
                "paper model and on the extended model; the full study: [control/control.md](control/control.md).",
                "", *_table(rows, [c for c in cols if any(c in r for r in rows)])]
    return []


def write_run_report(out: Path, dataset: Path, records: list, diag=None, results: dict | None = None) -> Path:
    """Write ``out/report.md`` from the steps' records; returns its path."""
    out = Path(out)
    md = [f"# mpc-actuator report: {dataset.name}", "",
          f"Dataset `{dataset}`. Steps: " + ", ".join(
              f"{r.step} ({'skipped' if r.skipped else ('failed' if r.failed else f'{r.wall_s:.0f} s')})" for r in records) + ".", ""]
    for rec in records:
        md += [f"## {TITLES[rec.step]} ({rec.step})", ""]
        if rec.skipped:
            md += [f"Not run: {rec.skipped}.", ""]
            continue
        if rec.failed:
            md += [f"**Failed** on this sample's model: {rec.failed}", ""]
            continue
        if rec.step == "check":
            md += ["```", rec.summary, "```", ""]
        elif rec.step == "identify":
            md += _section_identify(out, results)
        elif rec.step == "diagnose":
            md += _section_diagnose(out, diag)
        elif rec.summary:
            md += [rec.summary.splitlines()[0] + ".", ""]
        md += _section_rows(rec)
        if rec.step == "uncertainty":
            md += _include(out, "uncertainty/uncertainty.md", "Parameter uncertainty")
        if rec.step == "design":
            md += _include(out, "design/design.md", "Design")
    md += ["## Step times", "", "| step | wall time [s] | files |", "|---|---|---|"]
    md += [f"| {r.step} | {'skipped' if r.skipped else f'{r.wall_s:.1f}'} | {len(r.files)} |" for r in records]
    md += ["", "## Index of figures and tables", ""]
    files = sorted({_rel(out, p) for r in records for p in r.files})
    figs = [f for f in files if f.endswith(".png")]
    tabs = [f for f in files if f.endswith((".csv", ".md")) and f != "report.md"]
    other = [f for f in files if f not in figs and f not in tabs]
    for title, group in (("Figures", figs), ("Tables", tabs), ("Other files", other)):
        if group:
            md += [f"**{title}** ({len(group)}):", "", *(f"- [{f}]({f})" for f in group), ""]
    (out / "report.md").write_text("\n".join(md) + "\n", encoding="utf-8")
    (out / "report.json").write_text(json.dumps({
        "format": "mpc-actuator-run/1", "dataset": str(dataset),
        "steps": [{"step": r.step, "skipped": r.skipped, "failed": r.failed, "wall_s": r.wall_s, "files": [_rel(out, p) for p in r.files],
                   "summary": r.summary} for r in records]}, indent=1) + "\n", encoding="utf-8")
    return out / "report.md"
