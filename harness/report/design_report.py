"""Files of ``mpc-actuator design`` (:class:`harness.analysis.design.run.DesignResult`).

* ``design.json``: targets, space, objective, hull, counts, the ranked candidates (every feasible design, grid
  and refined, SI keys with units), the trade-off front (indices into the candidates) and, when nothing is
  feasible, the nearest designs with what each misses; no NaN/Infinity (null).
* ``candidates.csv``: the ranked candidates, units in the column names (``probability_*`` and
  ``margin_pct`` are fractions/percent of the spec).
* ``design.md``: the spec and what is minimised, the top designs at three significant digits with units,
  the trade-off front, or, with no feasible design, the nearest designs and what they miss.
* ``figures/feasible_region.png`` (per (wt%, D): the lowest voltage meeting the spec over the gaps),
  ``figures/tradeoffs.png`` (stroke vs settling time and blocked force vs power of every grid design, the
  feasible ones marked), ``figures/tradeoff_front.png`` (objective vs linearised probability of every
  candidate, the front joined).

Figures follow :mod:`harness.report.style` (Agg canvas, no pyplot state).
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
from harness.analysis.design.advice import OBJECTIVE_LABELS, objective_key, shortfalls
from harness.report import style

__all__ = ["write_design_outputs", "sig", "TOP", "plot_tradeoff_front", "plot_feasible_region", "plot_tradeoffs"]

TOP = 15                 # designs in the Markdown table
COLS = ["rank", "source", "wt_pct", "diameter_mm", "gap_mm", "voltage_V", "current_A", "power_W", "blocked_force_N",
        "static_stroke_m", "stroke_m", "settling_s", "contact", "bandwidth_Hz", "pull_in_current_A", "margin_pct", "probability_linearised",
        "probability_mc", "probability_mc_se", "on_front", "refined_from"]


def sig(v, n: int = 3) -> str:
    """v at n significant digits without an exponent (28.1818 -> "28.2", 5.45455 -> "5.45", 0.0012345 ->
    "0.00123"); "-" for None/NaN, "inf" for infinity."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    v = float(v)
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    if v == 0:
        return "0"
    return f"{v:.{max(0, n - 1 - math.floor(math.log10(abs(v))))}f}"


def _prob(p, se=None) -> str:
    if p is None:
        return "-"
    return f"{p:.2f}" if se is None else f"{p:.2f} ± {se:.2f}"


def _clean(v):
    return None if isinstance(v, float) and not math.isfinite(v) else v


def _spec_text(t) -> str:
    parts = []
    for name, v, op, unit in (("stroke", t.stroke_mm, ">=", "mm"), ("blocked force", t.blocked_force_N, ">=", "N"),
                              ("2 % settling time", t.settling_ms, "<=", "ms"), ("current", t.max_current_A, "<=", "A"),
                              ("power", t.max_power_W, "<=", "W"), ("bandwidth", t.min_bandwidth_Hz, ">=", "Hz")):
        if v is not None:
            parts.append(f"{name} {op} {sig(v)} {unit}")
    parts.append("contact with the coil allowed" if t.allow_contact else "no contact with the coil")
    return ", ".join(parts)


def _space_text(sp) -> str:
    out = []
    for a, unit in zip(sp.axes, ("wt%", "mm", "mm", "V")):
        label = {"wt_pct": "filler", "diameter_mm": "D", "gap_mm": "gap", "voltage_V": "voltage"}[a.name]
        out.append(f"{label} {sig(a.lo)} {unit}" if a.n == 1 else f"{label} {sig(a.lo)}-{sig(a.hi)} {unit} ({a.n} points)")
    return ", ".join(out)


def _design_cells(c) -> list:
    return [sig(c["wt_pct"]), sig(c["diameter_mm"]), sig(c["gap_mm"]), sig(c["voltage_V"]), sig(c["power_W"]),
            sig(c["current_A"]), sig(c["stroke_m"] * 1e3), sig(c["blocked_force_N"]), sig(c["settling_s"] * 1e3),
            sig(c["bandwidth_Hz"])]


_HEAD = ("wt% | D [mm] | gap [mm] | V [V] | power [W] | current [A] | stroke [mm] | blocked force [N] | "
         "settling [ms] | bandwidth [Hz]")


def _table(rows, extra_head: str, extra) -> list:
    head = f"| # | source | {_HEAD} | {extra_head} |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for i, c in rows:
        lines.append("| " + " | ".join([str(i + 1), c["source"]] + _design_cells(c) + extra(c)) + " |")
    return lines


def _markdown(result) -> list:
    st, t = result.settings, result.targets
    label = OBJECTIVE_LABELS[st.objective]
    cand = result.candidates
    n_grid = sum(1 for c in cand if c["source"] == "grid")
    n_ref = len(cand) - n_grid
    n_mc = sum(1 for c in cand if c.get("probability_mc") is not None)
    n_robust = sum(1 for c in cand if (c.get("probability_linearised") or 0) >= st.min_probability)
    lines = ["# Design advice", "", f"**Spec:** {_spec_text(t)}.", "",
             f"**Minimised:** {label} (`--minimise {st.objective}`).", "",
             f"**Space:** {_space_text(result.space)}; identified samples' hull: {result.hull}.", ""]
    if result.outside_hull:
        lines += [f"{result.outside_hull} of the grid's {result.space.wt_pct.n * result.space.diameter_mm.n} "
                  "(wt%, D) points lie outside the identified samples' convex hull (taken in the surfaces' log "
                  "coordinates) and are left out: the surfaces do not extrapolate.", ""]
    if not cand:
        near = result.nearest
        lines += [f"**No design of the {result.evaluated} in the space meets the spec** with the identified "
                  f"(nominal) parameters. The {len(near)} nearest designs (largest margin first) and what each "
                  "misses:", ""]
        lines += _table(list(enumerate(near)), "margin [%] | misses | P(spec) lin.",
                        lambda c: [f"{c['margin_pct']:.1f}", "; ".join(_miss(s) for s in shortfalls(t, c)),
                                   _prob(c.get("probability_linearised"))])
        lines += ["", "Widen the space where the nearest designs sit on its edge (`--voltage-V`, `--gap-mm`; "
                  "`--wt-pct` and `--diameter-mm` only inside the hull) or relax the target they miss."]
        return lines
    lines += [f"{n_grid} of {result.evaluated} grid designs meet the spec with the identified (nominal) "
              f"parameters; {n_ref} refined off the grid (local optimisation from the best "
              f"{st.refine}). Every design has its linearised (delta-method) probability of meeting the spec; "
              f"the first {n_mc} also a Monte-Carlo one ({st.n_draws} parameter draws, ± binomial standard "
              f"error). Ranked first: the {n_robust} designs whose linearised probability reaches "
              f"{st.min_probability:g} (`--min-probability`; refined designs are refined to keep it), each group by "
              f"{label}.", "", f"## The {min(TOP, len(cand))} best designs by {label}", ""]
    lines += _table(list(enumerate(cand[:TOP])), "margin [%] | P(spec) lin. | P(spec) MC",
                    lambda c: [f"{c['margin_pct']:.1f}", _prob(c["probability_linearised"]),
                               _prob(c.get("probability_mc"), c.get("probability_mc_se"))])
    refined = [c for c in cand[:TOP] if c["source"] == "refined"]
    if refined:
        lines += ["", "Refined designs start from: " + "; ".join(
            f"#{cand.index(c) + 1} from ({c['refined_from']})" for c in refined) + "."]
    lines += ["", f"## Trade-off front: {label} vs probability of meeting the spec", "",
              f"Designs no other design beats in both {label} and linearised probability "
              f"({len(result.front)}; figure `figures/tradeoff_front.png`):", ""]
    lines += _table([(i, cand[i]) for i in result.front[:TOP]], "margin [%] | P(spec) lin.",
                    lambda c: [f"{c['margin_pct']:.1f}", _prob(c["probability_linearised"])])
    lines += ["", "Margin: the smallest relative margin over the targets (0 %: on the spec). A refined design "
              "sits on a constraint (margin near 0 %): its probability is about 0.5 when that target's metric is "
              "uncertain; pick along the front for robustness."]
    return lines


def _miss(s) -> str:
    opt, val, lim, unit = s
    if opt == "--allow-contact":
        return "reaches the coil (contact)"
    return f"{opt} {sig(lim)}: {sig(val)} {unit}"


def _spec_title(result) -> str:
    return "spec: " + _spec_text(result.targets).replace(">=", "≥").replace("<=", "≤")


@style.styled
def plot_tradeoff_front(result, path: Path) -> Path:
    """Objective against the linearised probability of meeting the spec, every candidate; the front joined.

    Parameters
    ----------
    result : harness.analysis.design.run.DesignResult
        The design run (space, targets, metrics, feasibility, candidates, front, settings).
    path : Path
        Image file to write (its name made safe).

    Returns
    -------
    Path
        The written file.
    """
    cand = result.candidates
    key = objective_key(result.settings.objective)
    x = np.array([c[key] for c in cand], float)
    y = np.array([np.nan if c["probability_linearised"] is None else c["probability_linearised"] for c in cand])
    fig = style.new_figure(6.0, 4.2)
    ax = fig.subplots()
    grid = np.array([c["source"] == "grid" for c in cand])
    ax.scatter(x[grid], y[grid], s=6, c="0.6", label="grid designs meeting the spec")
    if (~grid).any():
        ax.scatter(x[~grid], y[~grid], s=40, marker="*", c="C3", label="refined designs")
    f = np.array(result.front, dtype=int)
    if f.size:
        ax.plot(x[f], y[f], "-o", c="C0", ms=3, lw=1, label="trade-off front")
    head, _, unit = style.key_label(key).rpartition(" (")
    ax.set_xlabel(f"{head}, minimised ({unit}")
    ax.set_ylabel(style.label("Probability of meeting the spec (linearised)", "1"))
    ax.set_ylim(-0.03, 1.03)
    ax.legend(fontsize=6, loc="lower right")
    style.suptitle(fig, "Design trade-off front\n" + _spec_title(result), fontsize=8)
    return style.save(fig, path)


@style.styled
def plot_feasible_region(result, path: Path) -> Path:
    """Per (wt%, D) of the grid, the lowest voltage meeting the spec over the gaps; infeasible cells marked.

    Parameters
    ----------
    result : harness.analysis.design.run.DesignResult
        The design run (space, targets, metrics, feasibility, candidates, front, settings).
    path : Path
        Image file to write (its name made safe).

    Returns
    -------
    Path
        The written file.
    """
    sp = result.space
    W, D, _, V = (a.values for a in sp.axes)
    ok = result.feasible
    vmin = np.where(ok, V[None, None, None, :], np.inf).min(axis=(2, 3))          # (n_w, n_D)
    fig = style.new_figure(6.0, 4.2)
    ax = fig.subplots()
    Z = np.where(np.isfinite(vmin), vmin, np.nan)
    if W.size > 1 and D.size > 1:
        m = ax.pcolormesh(W, D, Z.T, shading="nearest", cmap="viridis")
    else:
        m = ax.scatter(np.repeat(W, D.size), np.tile(D, W.size), c=Z.ravel(), cmap="viridis", s=60)
    fig.colorbar(m, ax=ax, label=style.label("Lowest voltage meeting the spec $V$", "V"))
    out = ~np.isfinite(result.metrics["current_A"][:, :, 0, 0])                    # left out: outside the hull
    bad = ~np.isfinite(vmin) & ~out
    ww, dd = np.meshgrid(W, D, indexing="ij")
    if bad.any():
        ax.scatter(ww[bad], dd[bad], marker="x", color="0.4", s=12, label="no design meets the spec")
    if out.any():
        ax.scatter(ww[out], dd[out], marker=".", color="0.7", s=10, label="outside the samples' hull")
    if bad.any() or out.any():
        ax.legend(fontsize=6, loc="upper left")
    ax.set_xlabel(style.label("Filler fraction", "wt%"))
    ax.set_ylabel(style.label("Diameter $D$", "mm"))
    ax.grid(False)
    style.suptitle(fig, "Feasible region over the generalization surfaces\n" + _spec_title(result), fontsize=8)
    return style.save(fig, path)


@style.styled
def plot_tradeoffs(result, path: Path) -> Path:
    """Stroke against settling time (coloured by power) and blocked force against power of the grid designs.

    Parameters
    ----------
    result : harness.analysis.design.run.DesignResult
        The design run (space, targets, metrics, feasibility, candidates, front, settings).
    path : Path
        Image file to write (its name made safe).

    Returns
    -------
    Path
        The written file.
    """
    m, ok = result.metrics, result.feasible.ravel()
    rng = np.random.default_rng(0)
    n = ok.size
    pick = np.arange(n) if n <= 20000 else np.sort(rng.choice(n, 20000, replace=False))
    fig = style.new_figure(7.2, 3.4)
    a1, a2 = fig.subplots(1, 2)
    x = m["settling_s"].ravel()[pick] * 1e3
    y = m["stroke_m"].ravel()[pick] * 1e3
    P = m["power_W"].ravel()[pick]
    s = a1.scatter(x, y, c=P, s=4, cmap="plasma")
    a1.scatter(x[ok[pick]], y[ok[pick]], s=10, facecolors="none", edgecolors="k", lw=0.5, label="meets the spec")
    fig.colorbar(s, ax=a1, label=style.label("Coil power $P$", "W"))
    a1.set_xlabel(style.label("2 % settling time", "ms"))
    a1.set_ylabel(style.label("Stroke", "mm"))
    a1.set_title("a) stroke and settling time", loc="left")
    a1.legend(fontsize=6)
    a2.scatter(P, m["blocked_force_N"].ravel()[pick], s=4, c="0.5")
    a2.scatter(P[ok[pick]], m["blocked_force_N"].ravel()[pick][ok[pick]], s=6, c=style.COLORS[2], label="meets the spec")
    a2.set_xlabel(style.label("Coil power $P$", "W"))
    a2.set_ylabel(style.label("Blocked force at the gap $F_\\mathrm{b}$", "N"))
    a2.set_title("b) blocked force and power", loc="left")
    a2.legend(fontsize=6)
    style.suptitle(fig, f"Trade-offs of the design grid ({n} designs)\n" + _spec_title(result), fontsize=8)
    return style.save(fig, path)


def _rows(result) -> list:
    front = set(result.front)
    out = []
    for i, c in enumerate(result.candidates):
        r = {k: _clean(c.get(k)) for k in COLS}
        r.update(rank=i + 1, on_front=i in front)
        out.append(r)
    return out


def write_design_outputs(result, out: Path) -> list:
    """Write the design job's files into ``out`` (module docstring); returns the paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = _rows(result)
    t = result.targets
    st = result.settings
    nearest = [dict({k: _clean(v) for k, v in c.items()},
                    misses=[{"option": o, "value": v, "limit": lim, "unit": u} for o, v, lim, u in shortfalls(t, c)])
               for c in result.nearest]
    data = {"format": "mpc-actuator-design/2", "targets": t.to_json(), "space": result.space.to_json(),
            "minimise": st.objective, "minimised_key": objective_key(st.objective),
            "min_probability": st.min_probability, "hull": result.hull,
            "designs_evaluated": int(result.evaluated),
            "grid_points_outside_hull": int(result.outside_hull),
            "designs_feasible": sum(1 for c in result.candidates if c.get("source", "grid") == "grid"),
            "designs_refined": sum(1 for c in result.candidates if c.get("source") == "refined"),
            "probability_draws": st.n_draws,
            "candidates_with_probability_mc": sum(1 for c in result.candidates if c.get("probability_mc") is not None),
            "candidates": rows, "front": list(result.front), "nearest": nearest}
    p = out / "design.json"
    p.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")
    written = [p]
    q = out / "candidates.csv"
    with q.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLS)
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if r[k] is None else r[k]) for k in COLS})
    written.append(q)
    r = out / "design.md"
    r.write_text("\n".join(_markdown(result)) + "\n")
    written.append(r)
    written.append(plot_feasible_region(result, out / "figures" / "feasible_region.png"))
    written.append(plot_tradeoffs(result, out / "figures" / "tradeoffs.png"))
    if result.candidates:
        written.append(plot_tradeoff_front(result, out / "figures" / "tradeoff_front.png"))
    return written
