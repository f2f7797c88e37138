"""Tables, figures and files of ``mpc-actuator uncertainty`` and ``mpc-actuator design``.

Uncertainty: ``uncertainty.json`` (:func:`harness.analysis.identification.parameter_uncertainty.uncertainty_to_json`),
``parameter_uncertainty.md``/``.csv`` (value, standard uncertainty, 95 % interval and how it was had, per
sample and parameter), ``prediction_bands.md``/``.csv`` (per sample and test: the band of the steady
value, the measured value, the share of measured points inside the prediction band),
``bands/<sample>/<test>.csv`` (the whole band) and ``figures/bands_<sample>.png``.

Design: :mod:`harness.report.design_report` (``write_design_outputs`` is re-exported here).
Figures are drawn on matplotlib Figures with the Agg canvas (no pyplot state).
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from harness.analysis.uncertainty.bands import band_summary_row
from harness.analysis.identification.parameter_uncertainty import PARAMS, uncertainty_to_json
from harness.data.paramsjson import KEYS
from harness.report.design_report import write_design_outputs

__all__ = ["write_uncertainty_outputs", "write_design_outputs", "parameter_rows"]


def _save(fig: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110)
    return path


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _table(rows: list, path_md: Path, path_csv: Path, title: str, notes: str = "") -> list:
    cols = list(rows[0]) if rows else []
    lines = [f"# {title}", "", "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(_fmt(r[c]) for c in cols) + " |" for r in rows]
    if notes:
        lines += ["", notes]
    path_md.write_text("\n".join(lines) + "\n")
    with path_csv.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({c: ("" if r[c] is None else r[c]) for c in cols})
    return [path_md, path_csv]


def parameter_rows(uncs: dict) -> list:
    """One row per sample and parameter: value, standard uncertainty, relative [%], 95 % interval, method."""
    rows = []
    for sid, u in uncs.items():
        for n, v, s in zip(PARAMS, u.mean, u.sd):
            lo, hi = u.intervals.get(n, (float("nan"), float("nan")))
            rows.append({"sample": sid, "parameter": KEYS[n], "value": float(v), "std": float(s),
                         "std_pct": 100.0 * float(s) / abs(v) if v else None, "ci95_lo": lo, "ci95_hi": hi,
                         "method": u.methods.get(n, "")})
    return rows


def _band_csv(band, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    unit = "mm" if band.column == "displacement_mm" else "N"
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow([band.axis_name, f"p2.5_{unit}", f"p50_{unit}", f"p97.5_{unit}", f"measured_{unit}"])
        meas = band.measured if band.measured is not None else np.full(band.axis.size, np.nan)
        for row in zip(band.axis, band.lo, band.med, band.hi, meas):
            w.writerow([f"{v:.9g}" for v in row])
    return path


def _band_figure(sid: str, bands: dict, path: Path) -> Path:
    n = len(bands)
    ncols = 4 if n > 4 else n
    nrows = int(math.ceil(n / ncols))
    fig = Figure(figsize=(4.0 * ncols, 2.8 * nrows))
    axes = np.atleast_1d(fig.subplots(nrows, ncols)).ravel()
    for ax, (name, b) in zip(axes, bands.items()):
        if b.measured is not None:
            ax.plot(b.axis, b.measured, ".", ms=1.5 if b.axis_name == "time_s" else 4, color="0.5", label="measured")
        ax.fill_between(b.axis, b.lo, b.hi, color="C0", alpha=0.35, label="95 % band (parameters)")
        ax.plot(b.axis, b.med, color="C0", lw=1, label="median")
        ax.set_title(f"{name}: {b.inside_pct:.0f} % of points in prediction band", fontsize=8)
        ax.set_xlabel(b.axis_name)
        ax.set_ylabel(b.column)
    for ax in axes[n:]:
        ax.set_visible(False)
    axes[0].legend(fontsize=6)
    fig.suptitle(f"{sid}: Monte-Carlo prediction bands")
    fig.tight_layout()
    return _save(fig, path)


def write_uncertainty_outputs(result, out: Path) -> list:
    """Write the uncertainty job's files into ``out`` (module docstring); returns the paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    st = result.settings
    data = uncertainty_to_json(result.uncertainties, result.unseen,
                               {"n_boot": st.n_boot, "n_draws": st.n_draws, "seed": st.seed, "grid": st.grid})
    data["skipped"] = dict(result.skipped)
    p = out / "uncertainty.json"
    p.write_text(json.dumps(data, indent=2) + "\n")
    written = [p]
    written += _table(parameter_rows(result.uncertainties), out / "parameter_uncertainty.md",
                      out / "parameter_uncertainty.csv", "Parameter uncertainty (SI units; keys carry the unit)",
                      "C and m: with R, L, Em, K1, K2 held (their correlation with C, m is neglected).")
    rows = []
    for sid, bands in result.bands.items():
        for name, b in bands.items():
            rows.append(band_summary_row(sid, b))
            written.append(_band_csv(b, out / "bands" / sid / f"{name}.csv"))
        if bands:
            written.append(_band_figure(sid, bands, out / "figures" / f"bands_{sid}.png"))
    if rows:
        unseen = ", ".join(result.unseen) or "none"
        written += _table(rows, out / "prediction_bands.md", out / "prediction_bands.csv",
                          "Monte-Carlo prediction bands (2.5/50/97.5 % of the draws)",
                          f"Predicted through the generalization surfaces (one fit per draw): {unseen}. "
                          f"inside_band_pct: measured points inside the band widened by +-1.96 sensor noise floors.")
    return written
