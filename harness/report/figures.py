"""Figures of measured vs simulated responses (paper Figures 4-8) and diagnostics.

Everything is drawn on :class:`matplotlib.figure.Figure` objects rendered by the
Agg canvas; pyplot is never imported, so no global figure state is created or
leaked and no display is needed. Each function writes one PNG (or any format
matplotlib infers from the suffix) and returns its path.

Units: time s, voltage V, current A, displacement mm, force N, gap mm.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

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
]

QUANTITY_LABELS = {
    "displacement_mm": "Displacement (mm)",
    "force_N": "Blocked force (N)",
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
# panel order of the paper's Figures 5, 7 and 8 (T8 appended)
PANEL_ORDER = ("RL", "T3", "T5", "T2", "T4", "T6", "T1", "T7", "T8")

C_MEAS = "0.25"        # measured: dark grey
C_SIM = "tab:red"      # simulated
C_I_MEAS = "tab:blue"
C_I_SIM = "tab:cyan"
DPI = 110


def _new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | Path) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p, dpi=DPI)
    return p


def _arr(x: Any) -> np.ndarray | None:
    return None if x is None else np.asarray(x, dtype=float)


def _label(quantity: str | None) -> str:
    if quantity is None:
        return "Response"
    return QUANTITY_LABELS.get(quantity, quantity)


def _measured_line(ax, x, y, label="measured"):
    """Measured data: thin dark line (dense records) or markers (few points)."""
    if y.size > 200:
        ax.plot(x, y, color=C_MEAS, lw=0.7, alpha=0.8, label=label)
    else:
        ax.plot(x, y, "o", color=C_MEAS, ms=3.5, mfc="none", label=label)


# --------------------------------------------------------------------------- single run
@dataclass(frozen=True)
class StepTraces:
    """One simulated run against time: time [s], voltage [V], current [A], displacement [mm], force [N]."""
    time_s: Any
    voltage_V: Any
    current_A: Any
    displacement_mm: Any
    force_N: Any


def plot_default_step(path: str | Path, traces: StepTraces,
                      title: str = "FMU default experiment: voltage step") -> Path:
    """Four stacked panels of one simulated run against time [s].

    Parameters
    ----------
    path : str or Path
        Image file to write.
    traces : StepTraces
        Voltage [V], current [A], displacement [mm] and magnetic force [N] against time [s].
    title : str
        Figure title.

    Returns
    -------
    Path
        The written file.
    """
    t = np.asarray(traces.time_s, dtype=float)
    fig = _new_figure(7.5, 8.0)
    axes = fig.subplots(4, 1, sharex=True)
    for ax, y, lab, c in zip(axes, (traces.voltage_V, traces.current_A, traces.displacement_mm, traces.force_N),
                             ("Voltage (V)", "Current (A)", "Displacement (mm)", "Force (N)"),
                             ("k", "tab:blue", C_SIM, "tab:purple")):
        ax.plot(t, np.asarray(y, dtype=float), color=c, lw=1.3)
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("Time (s)")
    fig.suptitle(title)
    return _save(fig, path)


# --------------------------------------------------------------------------- per sample
def _time_panel(ax, run: Mapping[str, Any], title: str, periodic: bool = False) -> None:
    t = np.asarray(run["time_s"], dtype=float)
    ym = _arr(run.get("y_meas"))
    if ym is not None:
        _measured_line(ax, t, ym, label="measured")
    ax.plot(t, np.asarray(run["y_sim"], dtype=float), color=C_SIM, lw=1.4, label="simulated")
    ax.set_xlabel("Time (s)")
    ax.set_ylabel(_label(run.get("quantity")))
    ax.grid(alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    Im, Is = _arr(run.get("current_A_meas")), _arr(run.get("current_A_sim"))
    axI = None
    if Im is not None or Is is not None:
        axI = ax.twinx()
        if Im is not None:
            axI.plot(t, Im, color=C_I_MEAS, lw=0.6, alpha=0.35, label="I measured")
        if Is is not None:
            axI.plot(t, Is, color=C_I_SIM, lw=1.0, ls="--", alpha=0.8, label="I simulated")
        axI.set_ylabel("Current (A)", color=C_I_MEAS)
        axI.tick_params(axis="y", colors=C_I_MEAS)
        h2, l2 = axI.get_legend_handles_labels()
        handles, labels = handles + h2, labels + l2
        ax.set_zorder(axI.get_zorder() + 1)  # response drawn over the current
        ax.patch.set_visible(False)
    if periodic:  # leave head room for the legend above the oscillation
        for a in (ax, axI):
            if a is not None:
                lo, hi = a.get_ylim()
                a.set_ylim(lo, hi + 0.35 * (hi - lo))
        ax.legend(handles, labels, loc="upper center", fontsize=7, ncols=len(handles))
    else:
        ax.legend(handles, labels, loc="lower right", fontsize=7)
    ax.set_title(title, fontsize=10)


def _rl_panel(ax, run: Mapping[str, Any], title: str) -> None:
    t = np.asarray(run["time_s"], dtype=float)
    Im, Is = _arr(run.get("current_A_meas")), _arr(run.get("current_A_sim"))
    if Im is not None:
        _measured_line(ax, t, Im, label="I measured")
    if Is is not None:
        ax.plot(t, Is, color=C_SIM, lw=1.4, label="I simulated")
    V = _arr(run.get("voltage_V"))
    if V is not None:
        axV = ax.twinx()
        axV.plot(t, V, color="0.6", lw=0.8, ls=":", label="V")
        axV.set_ylabel("Voltage (V)", color="0.45")
        axV.tick_params(axis="y", colors="0.45")
    ax.set_xlabel("Time (s)")
    ax.set_ylabel("Current (A)")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=7)
    ax.set_title(title, fontsize=10)


def _sweep_panel(ax, run: Mapping[str, Any], title: str) -> None:
    gap = np.asarray(run["gap_mm"], dtype=float)
    ym = _arr(run.get("y_meas"))
    gap_sim = _arr(run.get("gap_mm_sim"))
    gs = gap if gap_sim is None else gap_sim
    if ym is not None:
        ax.plot(gap, ym, "o", color=C_MEAS, ms=4, mfc="none", label="measured")
    order = np.argsort(gs)
    ax.plot(gs[order], np.asarray(run["y_sim"], dtype=float)[order], color=C_SIM, lw=1.4,
            label="simulated")
    ax.set_xlabel("Gap (mm)")
    ax.set_ylabel(_label(run.get("quantity")))
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=7)
    ax.set_title(title, fontsize=10)


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
    fig = _new_figure(5.2 * ncols, 3.6 * nrows)
    axes = np.atleast_1d(fig.subplots(nrows, ncols)).ravel()
    for i, (key, run) in enumerate(panels):
        ax = axes[i]
        letter = chr(ord("a") + i)
        if key == "RL":
            _rl_panel(ax, run, f"{letter}) RL circuit, T5 current")
            continue
        title = f"{letter}) {run.get('title', TEST_TITLES.get(key, key))}"
        if "gap_mm" in run:
            _sweep_panel(ax, run, title)
        else:
            _time_panel(ax, run, title, periodic=(key == "T6"))
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    suptitle = f"Sample {sample_id}: simulated vs measured"
    if synthetic:
        suptitle += " (synthetic data)"
    fig.suptitle(suptitle, fontsize=13)
    return _save(fig, path)


# --------------------------------------------------------------------------- residuals
def plot_residuals(path: str | Path, residuals: Mapping[str, tuple[Any, Any]],
                   residuals_after: Mapping[str, tuple[Any, Any]] | None = None,
                   title: str = "Residuals (simulated - measured)",
                   units: Mapping[str, str] | None = None) -> Path:
    """One residual-vs-time panel per test; optional second set drawn as "after".

    ``residuals`` maps a test id to ``(t [s], residual)``; the residual unit is
    ``units[test]`` if given, else N for T7/T8 and mm otherwise. For sweeps
    (T1/T7) pass the gap [mm] as first element; the x label then says gap.
    The legend shows the RMS of each set.

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
    fig = _new_figure(7.5, 2.2 * len(keys) + 0.6)
    axes = np.atleast_1d(fig.subplots(len(keys), 1)).ravel()
    for ax, k in zip(axes, keys):
        x, r = (np.asarray(v, dtype=float) for v in residuals[k])
        unit = units.get(k, "N" if k in ("T7", "T8") else "mm")
        lab = "before" if residuals_after is not None else "residual"
        ax.plot(x, r, color="tab:red", lw=0.8, marker="." if r.size <= 200 else None,
                label=f"{lab} (RMS {math.sqrt(float(np.mean(r ** 2))):.4g} {unit})")
        if residuals_after is not None and k in residuals_after:
            xa, ra = (np.asarray(v, dtype=float) for v in residuals_after[k])
            ax.plot(xa, ra, color="tab:green", lw=0.8, marker="." if ra.size <= 200 else None,
                    label=f"after (RMS {math.sqrt(float(np.mean(ra ** 2))):.4g} {unit})")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(f"{k} residual ({unit})")
        ax.set_xlabel("Gap (mm)" if k in ("T1", "T7") else "Time (s)")
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=7)
    fig.suptitle(title)
    return _save(fig, path)


# --------------------------------------------------------------------------- surface
@dataclass(frozen=True)
class SurfaceData:
    """A parameter identified at points of the (filler fraction, diameter) plane.

    ``name`` and ``unit`` label the value axis; ``wt_pct`` [wt%], ``diameter_mm`` [mm] and
    ``values`` (in ``unit``) are sequences of equal length, one entry per identified sample.
    """
    name: str
    unit: str
    wt_pct: Any
    diameter_mm: Any
    values: Any


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
    label = f"{name} ({unit})"
    fig = _new_figure(11.0, 4.6)
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    Zm = np.ma.masked_invalid(Z)
    ax3.plot_surface(W, D, Zm, cmap="viridis", alpha=0.75, linewidth=0, antialiased=True)
    ax3.scatter(w, d, v, color="tab:blue", s=30, depthshade=False, label="identified")
    ax3.set_xlabel("Filler (wt%)")
    ax3.set_ylabel("Diameter (mm)")
    ax3.set_zlabel(label)
    ax3.set_title(f"{name} surface fit")
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
    ax2.set_xlabel("Filler (wt%)")
    ax2.set_ylabel("Diameter (mm)")
    ax2.set_title(f"{name}: contour, identified points (dots)")
    return _save(fig, path)


# --------------------------------------------------------------------------- Pareto front
def plot_pareto(path: str | Path, F: Any, chosen_index: int | None,
                labels: Sequence[str]) -> Path:
    """Pairwise scatter of a k-objective Pareto front (k = 4 in the paper: 6 panels).

    ``F`` has shape (n_points, k); ``labels`` names the k objectives with units
    (e.g. "T3 STE (s)"). The point ``chosen_index`` (e.g. the min-J choice of
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
        One label per objective.

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
    pairs = [(i, j) for i in range(k) for j in range(i + 1, k)]
    ncols = min(3, len(pairs))
    nrows = math.ceil(len(pairs) / ncols)
    fig = _new_figure(4.2 * ncols, 3.6 * nrows)
    axes = np.atleast_1d(fig.subplots(nrows, ncols)).ravel()
    for ax, (i, j) in zip(axes, pairs):
        ax.scatter(F[:, i], F[:, j], s=14, color="0.45", alpha=0.7, label="Pareto set")
        if chosen_index is not None:
            ax.scatter(F[chosen_index, i], F[chosen_index, j], s=140, marker="*",
                       color="tab:red", edgecolor="k", zorder=3, label="chosen")
        ax.set_xlabel(labels[i])
        ax.set_ylabel(labels[j])
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=7)
    for ax in axes[len(pairs):]:
        ax.set_visible(False)
    fig.suptitle(f"Pareto front ({F.shape[0]} points)")
    return _save(fig, path)
