"""Tables, figures and files of ``mpc-actuator uncertainty`` and ``mpc-actuator design``.

Uncertainty: ``uncertainty.json`` (:func:`harness.analysis.identification.parameter_uncertainty.uncertainty_to_json`),
``parameter_uncertainty.md``/``.csv`` (value, standard uncertainty, 95 % interval and how it was had, per
sample and parameter), ``prediction_bands.md``/``.csv`` (per sample and test: the band of the steady
value, the measured value, the share of measured points inside the prediction band),
``bands/<sample>/<test>.csv`` (the whole band) and ``figures/bands_<sample>.png`` (:func:`plot_bands`).

Design: :mod:`harness.report.design_report` (``write_design_outputs`` is re-exported here).
Figures follow :mod:`harness.report.style` (Agg canvas, no pyplot state).
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from harness.analysis.uncertainty.bands import band_summary_row
from harness.analysis.identification.parameter_uncertainty import PARAMS, uncertainty_to_json
from harness.data.paramsjson import KEYS
from harness.report import figures, style
from harness.report.design_report import write_design_outputs

__all__ = ["write_uncertainty_outputs", "write_design_outputs", "parameter_rows", "plot_bands"]


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


Z95 = 1.959963984540054      # two-sided 95 % quantile of the normal: the prediction band is +-Z95 noise floors


@style.styled
def plot_bands(path: Path, sid: str, bands: dict) -> Path:
    """Prediction bands of one sample, one column block per test: on top the measured points, the median
    and the 95 % band of the parameter draws (filled, edges drawn) and the prediction band (that band widened
    by +-1.96 sensor noise floors, dashed); below, the same about the median, magnified, so a band thinner
    than the response's range stays legible. Titles give the share of measured points inside the prediction
    band (``inside_pct``) and the half-width of the parameter band beside the sensor noise; the figure title
    says what the coverage means.

    Parameters
    ----------
    path : Path
        Image file to write.
    sid : str
        Sample named in the figure title.
    bands : dict of str to harness.analysis.uncertainty.bands.Band
        Band per test (``axis_name`` "time_s" or "gap_mm", ``column`` "displacement_mm" or "force_N").

    Returns
    -------
    Path
        The written file.
    """
    n = len(bands)
    ncols = min(3, n)
    nrows = int(math.ceil(n / ncols))
    fig = style.new_figure(7.2, 2.8 * nrows + 0.9)
    grid = np.array(fig.subplots(2 * nrows, ncols, height_ratios=[2.2, 1.0] * nrows, squeeze=False))
    for k in range(n, nrows * ncols):                         # the empty slots of the last row
        r, c = divmod(k, ncols)
        grid[2 * r, c].set_visible(False)
        grid[2 * r + 1, c].set_visible(False)
    handles: list = []
    for i, (name, b) in enumerate(bands.items()):
        r, c = divmod(i, ncols)
        ax, dx = grid[2 * r, c], grid[2 * r + 1, c]
        dx.sharex(ax)
        x, lo, med, hi = (np.asarray(v, dtype=float) for v in (b.axis, b.lo, b.med, b.hi))
        w = Z95 * float(b.noise or 0.0)
        sweep = b.axis_name != "time_s"
        unit = "mm" if b.column == "displacement_mm" else "N"
        for a, off in ((ax, 0.0), (dx, med)):
            h = []
            if b.measured is not None:   # under the bands: dense noisy records must not hide them
                m = np.asarray(b.measured, dtype=float) - off
                h += a.plot(x, m, "o" if sweep else ".", ms=3 if sweep else 1.0, mfc="none" if sweep else None,
                            color=style.MEASURED, alpha=0.9 if sweep else 0.35, zorder=1, label="measured")
            if w > 0:
                h.append(a.fill_between(x, lo - off - w, hi - off + w, color=style.COLORS[0], alpha=0.12, lw=0,
                                        zorder=2, label="95 % prediction band"))
                a.plot(x, lo - off - w, x, hi - off + w, color=style.COLORS[0], lw=0.7, ls="--", zorder=3)
            h.append(a.fill_between(x, lo - off, hi - off, color=style.COLORS[0], alpha=style.BAND_ALPHA, lw=0,
                                    zorder=3, label="95 % band of the parameters"))
            a.plot(x, lo - off, x, hi - off, color=style.COLORS[0], lw=0.6, zorder=3)
            h += a.plot(x, med - off, color=style.COLORS[1], lw=0.9, zorder=4, label="median")
            handles = h if len(h) > len(handles) else handles
        if b.measured is not None:       # the magnified panel spans the bands and the bulk of the data
            dev = np.abs(np.asarray(b.measured, dtype=float) - med)
            span = max(float(np.nanmax(np.abs(np.r_[lo - med, hi - med]))) + w,
                       float(np.nanpercentile(dev, 99)) if dev.size else 0.0) or 1.0
            dx.set_ylim(-1.15 * span, 1.15 * span)
        half = 0.5 * float(np.nanmax(hi - lo))
        utext = style.unit_text(unit)
        note = f"band ±{half:.2g}" + (f", noise σ {b.noise:.2g}" if b.noise else "") + f" {utext}"
        ax.tick_params(labelbottom=False)
        ax.set_ylabel(style.key_label(b.column))
        dx.set_ylabel(style.label("− median", unit))
        dx.set_xlabel(style.key_label(b.axis_name))
        inside = "–" if not math.isfinite(b.inside_pct) else f"{b.inside_pct:.0f} %"
        ax.set_title(f"{figures.TEST_TITLES.get(name, name)}\n{inside} of points in the prediction band\n{note}",
                     loc="left", fontsize=6.5)
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=6.5)
    style.suptitle(fig, f"Sample {sid}: Monte-Carlo bands of the identified parameters (2.5-97.5 %)\n"
                 "prediction band = parameter band ± 1.96 σ sensor noise; coverage well below 95 % shows "
                 "model error that parameter uncertainty does not explain", fontsize=8)
    return style.save(fig, path)


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
            written.append(plot_bands(out / "figures" / f"bands_{sid}.png", sid, bands))
    if rows:
        unseen = ", ".join(result.unseen) or "none"
        written += _table(rows, out / "prediction_bands.md", out / "prediction_bands.csv",
                          "Monte-Carlo prediction bands (2.5/50/97.5 % of the draws)",
                          f"Predicted through the generalization surfaces (one fit per draw): {unseen}. "
                          f"inside_band_pct: measured points inside the band widened by +-1.96 sensor noise floors.")
    return written
