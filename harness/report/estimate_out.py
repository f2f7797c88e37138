"""Outputs of ``mpc-actuator estimate``: the EKF's estimate of a measured record (``harness.control.estimator``)
as a CSV (units in the column names) and a figure."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from harness.control.estimator import STATE_UNITS

_SAFE = {"m/s": "m_per_s", "1/T2": "per_T2", "1": "1"}


def column(name: str, prefix: str = "") -> str:
    """CSV column of a state: name and unit, e.g. v_m_per_s, std_x_m."""
    unit = STATE_UNITS[name]
    return f"{prefix}{name}_{_SAFE.get(unit, unit)}"


def write_estimate(out: Path, est: dict, measured: dict, title: str) -> list[Path]:
    """estimate.csv (time_s, the voltage and readings: V_V, x_read_m, I_read_A[, F_read_N], every estimated state and
    its standard deviation: x_m, v_m_per_s, ..., std_x_m, ...) and
    figures/estimate.png into ``out``; ``measured``: {column name with unit: array}."""
    out = Path(out)
    names = est["names"]
    cols = ["time_s", *measured, *(column(n) for n in names), *(column(n, "std_") for n in names)]
    data = np.column_stack([est["t_s"], *measured.values(), est["x"], est["std"]])
    path = out / "estimate.csv"
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        w.writerows([repr(float(v)) for v in row] for row in data)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    fig = Figure(figsize=(10, 2.4 * (len(names) + 1) / 2 + 1.5))
    FigureCanvasAgg(fig)
    n_ax = len(names)
    ncol = 2
    nrow = (n_ax + 1) // 2
    t = est["t_s"]
    for i, n in enumerate(names):
        ax = fig.add_subplot(nrow, ncol, i + 1)
        scale, unit = (1e3, "mm") if STATE_UNITS[n] == "m" else (1e3, "mm/s") if n == "v" else (1.0, STATE_UNITS[n])
        key = {"x": "x_read_m", "I": "I_read_A", "x_sensor": "x_read_m", "F_sensor": "F_read_N"}.get(n)
        if key in measured:
            ax.plot(t, scale * measured[key], ".", ms=1.5, color="0.6", label="reading")
        m, s = est["x"][:, i], est["std"][:, i]
        ax.plot(t, scale * m, "b", lw=1, label="estimate")
        ax.fill_between(t, scale * (m - 2 * s), scale * (m + 2 * s), color="b", alpha=0.2, lw=0, label="+-2 std")
        ax.set_ylabel(f"{n} [{unit}]")
        ax.set_xlabel("time [s]")
        if i == 0:
            ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fpath = out / "figures" / "estimate.png"
    fig.savefig(fpath, dpi=110)
    return [path, fpath]
