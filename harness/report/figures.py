"""Figures of measured vs simulated responses (paper Figures 4-8) and diagnostics.

Everything is drawn on :class:`matplotlib.figure.Figure` objects rendered by the
Agg canvas; pyplot is never imported, so no global figure state is created or
leaked and no display is needed. Each function writes one PNG (or any format
matplotlib infers from the suffix) and returns its path. All follow
:mod:`harness.report.style` (rcParams, page size, colours, labels "quantity (unit)").

Units: time s, voltage V, current A, displacement mm, force N, gap mm.
"""
from __future__ import annotations

import math
import textwrap
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from harness.report import style

__all__ = [
    "QUANTITY_LABELS",
    "TEST_TITLES",
    "StepTraces",
    "SurfaceData",
    "plot_default_step",
    "plot_sample_figure",
    "plot_residuals",
    "plot_surface",
    "plot_pareto",
    "PARAMETER_NAMES",
    "effect_text",
]

QUANTITY_LABELS = {
    "displacement_mm": style.label("Displacement $x$", "mm"),
    "force_N": style.label("Blocked force $F_\\mathrm{b}$", "N"),
}
TEST_TITLES = {  # paper Table 2
    "T1": "T1 displacement vs gap, 0.23 T",
    "T2": "T2 displacement step, 0.06 T",
    "T3": "T3 displacement step, 0.11 T",
    "T4": "T4 displacement step, 0.16 T",
    "T5": "T5 displacement step, 0.23 T",
    "T6": "T6 1 Hz sine, 0.23 T",
    "T7": "T7 blocked force vs gap, 0.23 T",
    "T8": "T8 blocked force step, 0.23 T, gap 2 mm",
}
#: model parameters as a paper writes them (name and symbol)
PARAMETER_NAMES = {
    "R": "Coil resistance $R$", "L": "Coil inductance $L$", "Em": "Coupling factor $E_\\mathrm{m}$",
    "K1": "Duffing coefficient $K_1$", "K2": "Spring constant $K_2$", "C": "Damping $C$",
    "m": "Moving mass $m$", "kB": "Field per ampere $k_B$", "ksat": "Saturation $k_\\mathrm{sat}$",
}
# panel order of the paper's Figures 5, 7 and 8 (T8 appended)
PANEL_ORDER = ("RL", "T3", "T5", "T2", "T4", "T6", "T1", "T7", "T8")

C_MEAS = style.MEASURED      # measured: grey
C_SIM = style.SIMULATED      # simulated
C_I_MEAS = "#56B4E9"         # current, measured (sky blue)
C_I_SIM = "#0072B2"          # current, simulated (blue)


def effect_text(effects) -> str:
    """Effect names for a title: ("filler_saturation", "coil_heating") -> "filler saturation + coil heating".

    Parameters
    ----------
    effects : str or sequence of str
        Effect names, or one string joining them with "+".

    Returns
    -------
    str
        The names with spaces, joined by " + ".
    """
    if isinstance(effects, str):
        effects = effects.split("+")
    return " + ".join(e.replace("_", " ") for e in effects)


def _tests_text(keys) -> str:
    """Tests for a title: T1..T8 all -> "tests T1-T8" (en dash), else "tests T1, T3" ("RL" counts as T5)."""
    tests = sorted({"T5" if k == "RL" else str(k) for k in keys})
    if tests == [f"T{i}" for i in range(1, 9)]:
        return "tests T1–T8"
    return ("test " if len(tests) == 1 else "tests ") + ", ".join(tests)


def _arr(x: Any) -> np.ndarray | None:
    return None if x is None else np.asarray(x, dtype=float)


def _label(quantity: str | None) -> str:
    if quantity is None:
        return "Response"
    return QUANTITY_LABELS.get(quantity) or style.key_label(quantity)


def _measured_line(ax, x, y, label="measured"):
    """Measured data: thin grey line (dense records) or open markers (few points)."""
    if y.size > 200:
        ax.plot(x, y, color=C_MEAS, lw=0.6, alpha=0.9, label=label)
    else:
        ax.plot(x, y, "o", color=C_MEAS, ms=3.5, mfc="none", label=label)


def _zero_based_ylim(ax, *ys) -> None:
    """Y limits spanning zero and the data (with a margin): a step's constant level is drawn as a level
    line at its height, not auto-zoomed into its rounding noise (11.9 V filling 11.25-12.5 V)."""
    y = np.concatenate([np.ravel(np.asarray(v, dtype=float)) for v in ys])
    y = y[np.isfinite(y)]
    if y.size == 0:
        return
    lo, hi = float(min(0.0, y.min())), float(max(0.0, y.max()))
    span = hi - lo or 1.0
    ax.set_ylim(lo - 0.06 * span if lo < 0 else lo - 0.04 * span, hi + 0.12 * span)


# --------------------------------------------------------------------------- single run
@dataclass(frozen=True)
class StepTraces:
    """One simulated run against time: time [s], voltage [V], current [A], displacement [mm], force [N]."""
    time_s: Any
    voltage_V: Any
    current_A: Any
    displacement_mm: Any
    force_N: Any


@style.styled
def plot_default_step(path: str | Path, traces: StepTraces, title: str | None = None) -> Path:
    """Four stacked panels of one simulated run against time [s]: voltage, current, displacement, force.

    Every panel's y axis spans zero and the trace, so the constant voltage of a step applied at t = 0 is a
    level line at its height.

    Parameters
    ----------
    path : str or Path
        Image file to write.
    traces : StepTraces
        Voltage [V], current [A], displacement [mm] and magnetic force [N] against time [s].
    title : str or None
        Figure title (None: "FMU default experiment: <V> V voltage step at t = 0").

    Returns
    -------
    Path
        The written file.
    """
    t = np.asarray(traces.time_s, dtype=float)
    V = np.asarray(traces.voltage_V, dtype=float)
    if title is None:
        title = f"FMU default experiment: {float(np.nanmax(np.abs(V))):.3g} V voltage step at $t$ = 0"
    fig = style.new_figure(6.0, 6.4)
    axes = fig.subplots(4, 1, sharex=True)
    for ax, y, lab, c in zip(axes, (V, traces.current_A, traces.displacement_mm, traces.force_N),
                             (style.label("Voltage $V$", "V"), style.label("Current $I$", "A"),
                              style.label("Displacement $x$", "mm"), style.label("Magnetic force $F$", "N")),
                             ("k", style.COLORS[0], C_SIM, style.COLORS[3])):
        y = np.asarray(y, dtype=float)
        ax.plot(t, y, color=c, lw=1.3)
        _zero_based_ylim(ax, y)
        ax.set_ylabel(lab)
    axes[-1].set_xlabel(style.label("Time $t$", "s"))
    axes[-1].set_xlim(t[0], t[-1])
    style.suptitle(fig, title)
    return style.save(fig, path)


# --------------------------------------------------------------------------- per sample
def _time_panel(ax, run: Mapping[str, Any], title: str, periodic: bool = False) -> None:
    t = np.asarray(run["time_s"], dtype=float)
    ym = _arr(run.get("y_meas"))
    if ym is not None:
        _measured_line(ax, t, ym, label="measured")
    ax.plot(t, np.asarray(run["y_sim"], dtype=float), color=C_SIM, lw=1.2, label="simulated")
    ax.set_xlabel(style.label("Time $t$", "s"))
    ax.set_ylabel(_label(run.get("quantity")))
    handles, labels = ax.get_legend_handles_labels()
    Im, Is = _arr(run.get("current_A_meas")), _arr(run.get("current_A_sim"))
    axI = None
    if Im is not None or Is is not None:
        axI = ax.twinx()
        if Im is not None:
            axI.plot(t, Im, color=C_I_MEAS, lw=0.6, alpha=0.5, label="$I$ measured")
        if Is is not None:
            axI.plot(t, Is, color=C_I_SIM, lw=0.9, ls="--", alpha=0.8, label="$I$ simulated")
        axI.set_ylabel(style.label("Current $I$", "A"), color=C_I_SIM)
        axI.tick_params(axis="y", colors=C_I_SIM)
        axI.grid(False)
        h2, l2 = axI.get_legend_handles_labels()
        handles, labels = handles + h2, labels + l2
        ax.set_zorder(axI.get_zorder() + 1)  # response drawn over the current
        ax.patch.set_visible(False)
    if periodic:  # leave head room for the legend above the oscillation
        for a in (ax, axI):
            if a is not None:
                lo, hi = a.get_ylim()
                a.set_ylim(lo, hi + 0.5 * (hi - lo))
        ax.legend(handles, labels, loc="upper center", fontsize=6, ncols=2)
    else:
        ax.legend(handles, labels, loc="lower right", fontsize=6)
    ax.set_title(title, loc="left")


def _rl_panel(ax, run: Mapping[str, Any], title: str) -> None:
    t = np.asarray(run["time_s"], dtype=float)
    Im, Is = _arr(run.get("current_A_meas")), _arr(run.get("current_A_sim"))
    if Im is not None:
        _measured_line(ax, t, Im, label="I measured")
    if Is is not None:
        ax.plot(t, Is, color=C_SIM, lw=1.2, label="$I$ simulated")
    V = _arr(run.get("voltage_V"))
    if V is not None:
        axV = ax.twinx()
        axV.plot(t, V, color="0.45", lw=0.8, ls=":", label="$V$")
        _zero_based_ylim(axV, V)
        axV.set_ylabel(style.label("Voltage $V$", "V"), color="0.45")
        axV.tick_params(axis="y", colors="0.45")
        axV.grid(False)
    ax.set_xlabel(style.label("Time $t$", "s"))
    ax.set_ylabel(style.label("Current $I$", "A"))
    ax.legend(loc="lower right", fontsize=6)
    ax.set_title(title, loc="left")


def _sweep_panel(ax, run: Mapping[str, Any], title: str) -> None:
    gap = np.asarray(run["gap_mm"], dtype=float)
    ym = _arr(run.get("y_meas"))
    gap_sim = _arr(run.get("gap_mm_sim"))
    gs = gap if gap_sim is None else gap_sim
    if ym is not None:
        ax.plot(gap, ym, "o", color=C_MEAS, ms=3.5, mfc="none", label="measured")
    order = np.argsort(gs)
    ax.plot(gs[order], np.asarray(run["y_sim"], dtype=float)[order], color=C_SIM, lw=1.2,
            label="simulated")
    ax.set_xlabel(style.label("Gap $r_0$", "mm"))
    ax.set_ylabel(_label(run.get("quantity")))
    ax.legend(loc="best", fontsize=6)
    ax.set_title(title, loc="left")


@style.styled
def plot_sample_figure(path: str | Path, sample_id: str, runs: Mapping[str, Mapping[str, Any]],
                       synthetic: bool = False, ncols: int = 3) -> Path:
    """Per-sample figure set like the paper's Figures 5, 7 and 8.

    ``runs`` maps a test id ("T1".."T8") to a dict of arrays:

    * time series (T2-T6, T8): ``time_s`` [s], ``voltage_V`` [V],
      ``current_A_meas``/``current_A_sim`` [A], ``y_meas``/``y_sim`` and
      ``quantity`` ("displacement_mm" or "force_N"); the response is drawn on
      the left axis, the current on a twin right axis;
    * sweeps (T1, T7): ``gap_mm`` [mm], ``y_meas``, ``y_sim`` (optionally on its
      own grid ``gap_mm_sim``) and ``quantity``; measured markers vs simulated line.

    A run may carry ``title`` to override the panel title. If T5 has currents,
    a first panel shows the RL-circuit current response (paper panel a).
    Missing tests are skipped; panels are lettered a), b), ... in paper order.

    Parameters
    ----------
    path : str or Path
        Image file to write.
    sample_id : str
        Sample named in the figure title.
    runs : mapping of str to mapping
        Traces per test, as above.
    synthetic : bool
        Mark the figure title "synthetic data".
    ncols : int
        Panels per row.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ValueError
        ``runs`` holds no test.
    """
    panels: list[tuple[str, Mapping[str, Any]]] = []
    for key in PANEL_ORDER:
        if key == "RL":
            r5 = runs.get("T5")
            if r5 is not None and "time_s" in r5 and (
                    r5.get("current_A_meas") is not None or r5.get("current_A_sim") is not None):
                panels.append(("RL", r5))
        elif key in runs:
            panels.append((key, runs[key]))
    extra = [k for k in runs if k not in PANEL_ORDER]
    panels += [(k, runs[k]) for k in sorted(extra)]
    if not panels:
        raise ValueError("runs: no test to plot")
    ncols = max(1, min(ncols, len(panels)))
    nrows = math.ceil(len(panels) / ncols)
    fig = style.new_figure(2.4 * ncols, 2.2 * nrows + 0.4)
    axes = np.atleast_1d(fig.subplots(nrows, ncols)).ravel()
    for i, (key, run) in enumerate(panels):
        ax = axes[i]
        letter = chr(ord("a") + i)
        if key == "RL":
            _rl_panel(ax, run, f"{letter}) RL circuit, T5 current")
            continue
        title = textwrap.fill(f"{letter}) {run.get('title', TEST_TITLES.get(key, key))}", 34, break_on_hyphens=False)
        if "gap_mm" in run:
            _sweep_panel(ax, run, title)
        else:
            _time_panel(ax, run, title, periodic=(key == "T6"))
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    suptitle = f"Sample {sample_id}: measured and simulated, {_tests_text(k for k, _ in panels)}"
    if synthetic:
        suptitle += " (synthetic data)"
    style.suptitle(fig, suptitle)
    return style.save(fig, path)


# --------------------------------------------------------------------------- residuals
@style.styled
def plot_residuals(path: str | Path, residuals: Mapping[str, tuple[Any, Any]],
                   residuals_after: Mapping[str, tuple[Any, Any]] | None = None,
                   title: str = "Residuals (simulated - measured)",
                   units: Mapping[str, str] | None = None, labels: tuple[str, str] = ("before", "after")) -> Path:
    """One residual panel per test, two columns from four tests on; an optional second set drawn as "after".

    ``residuals`` maps a test id to ``(t [s], residual)``; the residual unit is
    ``units[test]`` if given, else N for T7/T8 and mm otherwise; small residuals are shown in a smaller unit
    (:func:`harness.report.style.prefixed_unit`: 3e-5 N as 30 µN), not with a "1e-5" axis offset. For sweeps
    (T1/T7) pass the gap [mm] as first element; the x label then says gap.
    Each panel title gives the RMS of each set (before -> after). The "before" set is a broad translucent line
    under the "after" set's thin dark one, so both stay visible where they coincide; one legend for the figure.

    Parameters
    ----------
    path : str or Path
        Image file to write.
    residuals : mapping of str to (array, array)
        Per test: (time [s] or gap [mm], residual).
    residuals_after : mapping or None
        A second set drawn as "after" (e.g. the extended model).
    title : str
        Figure title.
    units : mapping of str to str or None
        Residual unit per test.
    labels : (str, str)
        Legend names of the two sets.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ValueError
        ``residuals`` is empty.
    """
    keys = list(residuals)
    if not keys:
        raise ValueError("residuals: empty")
    units = dict(units or {})
    ncols = 1 if len(keys) < 4 else 2
    nrows = math.ceil(len(keys) / ncols)
    fig = style.new_figure(7.0 if ncols == 2 else 6.0, 1.75 * nrows + 0.9)
    axes = np.atleast_1d(fig.subplots(nrows, ncols)).ravel()
    handles = []
    for ax, k in zip(axes, keys):
        x, r = (np.asarray(v, dtype=float) for v in residuals[k])
        unit = units.get(k, "N" if k in ("T7", "T8") else "mm")
        ra_raw = (np.asarray(residuals_after[k][1], dtype=float)
                  if residuals_after is not None and k in residuals_after else np.zeros(0))
        unit, scale = style.prefixed_unit(unit, np.r_[r, ra_raw])
        r = r * scale
        sparse = r.size <= 200
        h = ax.plot(*style.envelope(x, r), color=style.BEFORE, lw=2.2 if not sparse else 1.4, alpha=0.45, zorder=2,
                    marker="o" if sparse else None, ms=3.5, solid_capstyle="butt",
                    label=labels[0] if residuals_after is not None else "residual")
        rms = f"RMS {math.sqrt(float(np.mean(r ** 2))):.3g}"
        if residuals_after is not None and k in residuals_after:
            xa, ra = (np.asarray(v, dtype=float) for v in residuals_after[k])
            ra = ra * scale
            h += ax.plot(*style.envelope(xa, ra), color=style.AFTER, lw=0.6, alpha=0.9, zorder=3,
                         marker="." if ra.size <= 200 else None, ms=3.5, label=labels[1])
            rms += f" → {math.sqrt(float(np.mean(ra ** 2))):.3g}"
        handles = h if len(h) > len(handles) else handles
        ax.axhline(0.0, color="k", lw=0.5, zorder=1)
        test = k.split()[0]
        what = k[len(test):].strip()
        ax.set_title(TEST_TITLES.get(test, test) + (f" ({what})" if what else "")
                     + f"\n{rms} {style.unit_text(unit)}", loc="left")
        ax.set_ylabel(style.label("Residual", unit))
        is_sweep = test in ("T1", "T7")
        ax.set_xlabel(style.label("Gap $r_0$", "mm") if is_sweep else style.label("Time $t$", "s"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=7)
    for ax in axes[len(keys):]:
        ax.set_visible(False)
    style.suptitle(fig, title)
    return style.save(fig, path)


# --------------------------------------------------------------------------- surface
@dataclass(frozen=True)
class SurfaceData:
    """A parameter identified at points of the (filler fraction, diameter) plane.

    ``name`` and ``unit`` label the value axis; ``wt_pct`` [wt%], ``diameter_mm`` [mm] and
    ``values`` (in ``unit``) are sequences of equal length, one entry per identified sample; ``samples``
    optionally names them (in the figure title).
    """
    name: str
    unit: str
    wt_pct: Any
    diameter_mm: Any
    values: Any
    samples: Sequence[str] | None = None    # the identified samples (named in the title)


@style.styled
def plot_surface(path: str | Path, data: SurfaceData, grid_fn: Callable[[np.ndarray, np.ndarray], Any],
                 n_grid: int = 41) -> Path:
    """Figure-6-like view of a parameter over filler fraction and diameter.

    Left: 3-D surface of ``grid_fn(wt_grid, d_grid)`` (meshgrid arrays, wt% and mm) on an
    ``n_grid`` x ``n_grid`` grid spanning the points, with the identified points of ``data`` as
    dots; right: filled contour map with the same points. NaN grid values (e.g. outside an
    interpolant's hull) are left blank.

    Parameters
    ----------
    path : str or Path
        Image file to write.
    data : SurfaceData
        Name and unit of the parameter and its identified points.
    grid_fn : callable
        ``grid_fn(W [wt%], D [mm])`` -> values on the meshgrid arrays (e.g. the surface fit).
    n_grid : int
        Grid points per axis.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ValueError
        The points are empty or of unequal shapes, or ``grid_fn`` returns the wrong shape.
    """
    name, unit = data.name, data.unit
    w = np.asarray(data.wt_pct, dtype=float)
    d = np.asarray(data.diameter_mm, dtype=float)
    v = np.asarray(data.values, dtype=float)
    if not (w.shape == d.shape == v.shape) or w.size == 0:
        raise ValueError("wt_pct, diameter_mm and values must be non-empty and of equal shape")
    wg = np.linspace(w.min(), w.max(), n_grid)
    dg = np.linspace(d.min(), d.max(), n_grid)
    W, D = np.meshgrid(wg, dg)
    Z = np.asarray(grid_fn(W, D), dtype=float)
    if Z.shape != W.shape:
        raise ValueError(f"grid_fn: returned shape {Z.shape}, expected {W.shape}")
    quantity = PARAMETER_NAMES.get(name, name)
    label = style.label(quantity, unit)
    symbol = quantity.split()[-1] if "$" in quantity else name
    fig = style.new_figure(7.2, 3.4)
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    Zm = np.ma.masked_invalid(Z)
    ax3.plot_surface(W, D, Zm, cmap="viridis", alpha=0.75, linewidth=0, antialiased=True)
    ax3.scatter(w, d, v, color="tab:blue", s=30, depthshade=False, label="identified")
    ax3.set_xlabel(style.label("Filler fraction", "wt%"))
    ax3.set_ylabel(style.label("Diameter $D$", "mm"))
    ax3.set_title(f"a) {style.label(symbol, unit)}: surface fit, identified samples (dots)", loc="left")
    ax2 = fig.add_subplot(1, 2, 2)
    cs = ax2.contourf(W, D, Zm, levels=15, cmap="viridis")
    ax2.contour(W, D, Zm, levels=15, colors="k", linewidths=0.3)
    ax2.scatter(w, d, color="tab:blue", edgecolor="w", s=40, zorder=3, clip_on=False,
                label="identified")
    for wi, di, vi in zip(w, d, v):
        ax2.annotate(f"{vi:.3g}", (wi, di), textcoords="offset points", xytext=(5, 5),
                     fontsize=7, color="k", annotation_clip=False,
                     bbox=dict(boxstyle="round,pad=0.15", fc="w", ec="none", alpha=0.7))
    pad_w = 0.05 * (np.ptp(wg) or 1.0)
    pad_d = 0.05 * (np.ptp(dg) or 1.0)
    ax2.set_xlim(wg[0] - pad_w, wg[-1] + pad_w)
    ax2.set_ylim(dg[0] - pad_d, dg[-1] + pad_d)
    fig.colorbar(cs, ax=ax2, label=label)
    ax2.set_xlabel(style.label("Filler fraction", "wt%"))
    ax2.set_ylabel(style.label("Diameter $D$", "mm"))
    ax2.set_title("b) contours, values at the identified samples", loc="left")
    who = f" of {', '.join(data.samples)}" if data.samples else f" of {w.size} samples"
    style.suptitle(fig, f"{quantity} over filler fraction and diameter: surface fit{who}")
    return style.save(fig, path)


# --------------------------------------------------------------------------- Pareto front
@style.styled
def plot_pareto(path: str | Path, F: Any, chosen_index: int | None,
                labels: Sequence[str], sample_id: str | None = None) -> Path:
    """Pairwise scatter of a k-objective Pareto front (k = 4 in the paper: 6 panels).

    ``F`` has shape (n_points, k); ``labels`` names the k objectives, either as text with the unit in
    parentheses ("T3 STE (s)") or as keys with a unit suffix ("T3_ste_s", typeset by
    :func:`harness.report.style.key_label`; small values then take a smaller unit, 0.004 s as 4 ms). The point ``chosen_index`` (e.g. the min-J choice of
    Eq. 6) is highlighted; None: no highlight.

    Parameters
    ----------
    path : str or Path
        Image file to write.
    F : array, shape (n_points, k)
        Objective values of the front (units as in ``labels``).
    chosen_index : int or None
        Index of the chosen point.
    labels : sequence of str
        One label (or key) per objective.
    sample_id : str or None
        Sample named in the title.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ValueError
        Bad shape of ``F``, wrong number of labels, or ``chosen_index`` out of range.
    """
    F = np.asarray(F, dtype=float)
    if F.ndim != 2 or F.shape[0] == 0 or F.shape[1] < 2:
        raise ValueError(f"F: expected shape (n_points >= 1, k >= 2), got {F.shape}")
    k = F.shape[1]
    if len(labels) != k:
        raise ValueError(f"labels: expected {k} labels, got {len(labels)}")
    if chosen_index is not None and not (-F.shape[0] <= chosen_index < F.shape[0]):
        raise ValueError(f"chosen_index: {chosen_index} out of range for {F.shape[0]} points")
    F = F.copy()
    text = []
    for i, lab in enumerate(labels):
        if " " in lab or "(" in lab:     # already a label
            text.append(lab)
            continue
        name, unit = style.split_key(lab)
        head = style.key_label(lab).rpartition(" (")[0] if unit is not None else style.key_label(lab)
        if unit is not None:             # small objectives in a smaller unit (0.004 s as 4 ms), no axis offset
            unit, factor = style.prefixed_unit(unit, F[:, i])
            F[:, i] *= factor
        text.append(style.label(head, unit))
    pairs = [(i, j) for i in range(k) for j in range(i + 1, k)]
    ncols = min(3, len(pairs))
    nrows = math.ceil(len(pairs) / ncols)
    fig = style.new_figure(2.4 * ncols, 2.2 * nrows + 0.5)
    axes = np.atleast_1d(fig.subplots(nrows, ncols)).ravel()
    for ax, (i, j) in zip(axes, pairs):
        ax.scatter(F[:, i], F[:, j], s=10, color="0.4", alpha=0.7, label="Pareto set")
        if chosen_index is not None:
            ax.scatter(F[chosen_index, i], F[chosen_index, j], s=90, marker="*",
                       color=C_SIM, edgecolor="k", linewidths=0.5, zorder=3, label="chosen (min $J$)")
        ax.set_xlabel(text[i])
        ax.set_ylabel(text[j])
    axes[0].legend(loc="best", fontsize=6)
    for ax in axes[len(pairs):]:
        ax.set_visible(False)
    who = f"Sample {sample_id}: " if sample_id else ""
    style.suptitle(fig, f"{who}Pareto front of the identification ({F.shape[0]} points)")
    return style.save(fig, path)
