"""Tables, figures and files of ``mpc-actuator uncertainty`` and ``mpc-actuator design``.

Uncertainty: ``uncertainty.json`` (:func:`harness.analysis.uncertainty.uncertainty_to_json`),
``parameter_uncertainty.md``/``.csv`` (value, standard uncertainty, 95 % interval and how it was had, per
sample and parameter), ``prediction_bands.md``/``.csv`` (per sample and test: the band of the steady
value, the measured value, the share of measured points inside the prediction band),
``bands/<sample>/<test>.csv`` (the whole band) and ``figures/bands_<sample>.png``.

Design: ``design.json`` (targets, space, hull, counts, candidates), ``candidates.csv``, ``design.md`` and
``figures/feasible_region.png`` (per (wt%, D): the lowest voltage meeting the spec over the gaps, and
the best candidate's probability), ``figures/tradeoffs.png`` (stroke vs settling time and blocked force vs
power of every design, the feasible ones marked).
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

from harness.analysis.bands import band_summary_row
from harness.analysis.uncertainty import PARAMS, uncertainty_to_json
from harness.data.paramsjson import KEYS

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


# ============================================================================ design
def _feasible_figure(result, path: Path) -> Path:
    sp = result.space
    W, D, _, V = (a.values for a in sp.axes)
    ok = result.feasible
    vmin = np.where(ok, V[None, None, None, :], np.inf).min(axis=(2, 3))          # (n_w, n_D)
    fig = Figure(figsize=(6.5, 4.5))
    ax = fig.subplots()
    Z = np.where(np.isfinite(vmin), vmin, np.nan)
    if W.size > 1 and D.size > 1:
        m = ax.pcolormesh(W, D, Z.T, shading="nearest", cmap="viridis")
        fig.colorbar(m, ax=ax, label="lowest voltage meeting the spec [V]")
    else:
        ax.scatter(np.repeat(W, D.size), np.tile(D, W.size), c=Z.ravel(), cmap="viridis", s=60)
    bad = ~np.isfinite(vmin)
    ww, dd = np.meshgrid(W, D, indexing="ij")
    ax.scatter(ww[bad], dd[bad], marker="x", color="0.4", s=12, label="no design meets the spec")
    ax.set_xlabel("filler fraction [wt%]")
    ax.set_ylabel("diameter D [mm]")
    ax.set_title("feasible region over the generalization surfaces (grey x: infeasible)", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    return _save(fig, path)


def _tradeoff_figure(result, path: Path) -> Path:
    m, ok = result.metrics, result.feasible.ravel()
    rng = np.random.default_rng(0)
    n = ok.size
    pick = np.arange(n) if n <= 20000 else np.sort(rng.choice(n, 20000, replace=False))
    fig = Figure(figsize=(10, 4.2))
    a1, a2 = fig.subplots(1, 2)
    x = m["settling_s"].ravel()[pick] * 1e3
    y = m["stroke_m"].ravel()[pick] * 1e3
    P = m["power_W"].ravel()[pick]
    s = a1.scatter(x, y, c=P, s=4, cmap="plasma")
    a1.scatter(x[ok[pick]], y[ok[pick]], s=10, facecolors="none", edgecolors="g", lw=0.5, label="meets the spec")
    fig.colorbar(s, ax=a1, label="coil power [W]")
    a1.set_xlabel("2 % settling time [ms]")
    a1.set_ylabel("stroke [mm]")
    a1.legend(fontsize=7)
    a2.scatter(P, m["blocked_force_N"].ravel()[pick], s=4, c="0.5")
    a2.scatter(P[ok[pick]], m["blocked_force_N"].ravel()[pick][ok[pick]], s=6, c="g", label="meets the spec")
    a2.set_xlabel("coil power [W]")
    a2.set_ylabel("blocked force at the gap [N]")
    a2.legend(fontsize=7)
    fig.suptitle("trade-offs of the design grid")
    fig.tight_layout()
    return _save(fig, path)


def write_design_outputs(result, out: Path) -> list:
    """Write the design job's files into ``out`` (module docstring); returns the paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cand = result.candidates
    n_prob = sum(1 for c in cand if c["probability"] is not None)
    data = {"format": "mpc-actuator-design/1", "targets": result.targets.to_json(), "space": result.space.to_json(),
            "hull": result.hull, "designs_evaluated": int(result.space.size), "designs_feasible": len(cand),
            "probability_draws": result.settings.n_draws, "candidates_with_probability": n_prob,
            "candidates": [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in c.items()}
                           for c in cand]}
    p = out / "design.json"
    p.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")
    written = [p]
    cols = ["wt_pct", "diameter_mm", "gap_mm", "voltage_V", "current_A", "power_W", "blocked_force_N",
            "static_stroke_m", "stroke_m", "settling_s", "contact", "bandwidth_Hz", "probability", "probability_se"]
    q = out / "candidates.csv"
    with q.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for c in cand:
            w.writerow({k: ("" if c[k] is None else c[k]) for k in cols})
    written.append(q)
    lines = ["# Design", "", f"Targets: {json.dumps(result.targets.to_json())}", "",
             f"Space: {json.dumps(result.space.to_json())}", "", f"Identified samples' hull: {result.hull}", "",
             f"{len(cand)} of {result.space.size} designs meet the spec with the identified (nominal) parameters; "
             f"{n_prob} of them (largest margin first) were given a probability from {result.settings.n_draws} "
             f"parameter draws.", ""]
    if cand:
        lines += ["| wt% | D [mm] | gap [mm] | V [V] | stroke [mm] | blocked force [N] | settling [ms] | "
                  "power [W] | P(spec) |", "|---|---|---|---|---|---|---|---|---|"]
        best = sorted(cand[:max(n_prob, 1)], key=lambda c: -(c["probability"] or 0))[:15]
        for c in best:
            lines.append(f"| {c['wt_pct']:g} | {c['diameter_mm']:g} | {c['gap_mm']:g} | {c['voltage_V']:.3g} | "
                         f"{c['stroke_m'] * 1e3:.3g} | {c['blocked_force_N']:.3g} | {c['settling_s'] * 1e3:.3g} | "
                         f"{c['power_W']:.3g} | {_fmt(c['probability'])} |")
    r = out / "design.md"
    r.write_text("\n".join(lines) + "\n")
    written.append(r)
    written.append(_feasible_figure(result, out / "figures" / "feasible_region.png"))
    written.append(_tradeoff_figure(result, out / "figures" / "tradeoffs.png"))
    return written
