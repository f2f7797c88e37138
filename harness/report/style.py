"""One style for every figure the harness writes: rcParams, sizes, colours, labels with units, file names.

Every figure function of :mod:`harness.report` is decorated with :func:`styled` (it draws inside
``matplotlib.rc_context(RC)``, so nothing leaks into the caller's rcParams), creates its figure with
:func:`new_figure` (Agg canvas, constrained layout, size clamped to :data:`MAX_SIZE_IN`) and writes it with
:func:`save` (:data:`DPI`, a file name made safe by :func:`safe_name`). Labels are written by :func:`label`
("Displacement $x$ (mm)") or, from a column/JSON key, :func:`key_label` ("time_s" -> "Time $t$ (s)",
"T3_ste_s" -> "T3 settling-time error (s)"); units are typeset by :func:`unit_text` ("N.m/T2" -> "N·m/T²").
No figure shows a raw key. pyplot is never imported.
"""
from __future__ import annotations

import functools
import re
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import matplotlib as mpl
import numpy as np
from cycler import cycler
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["RC", "DPI", "MAX_SIZE_IN", "COLORS", "MEASURED", "SIMULATED", "BEFORE", "AFTER", "BAND_ALPHA",
           "styled", "new_figure", "suptitle", "save", "safe_name", "unit_text", "label", "key_label", "split_key",
           "QUANTITY_NAMES", "UNIT_SYMBOLS", "SMALLER_UNITS", "prefixed_unit"]

DPI = 200                      # print resolution of the written PNGs
MAX_SIZE_IN = (7.2, 9.0)       # a double-column page: width x height [in]
# Okabe-Ito palette: distinguishable with the common colour-vision deficiencies and in grey scale
COLORS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442", "#000000")
MEASURED = "0.35"              # measured data: grey
SIMULATED = "#D55E00"          # the model: vermilion
BEFORE = "#D55E00"             # residuals of the paper model (drawn first, solid)
AFTER = "#0072B2"              # residuals of the extended model (drawn over, dashed, translucent)
BAND_ALPHA = 0.3               # fill of an uncertainty band (its edges are drawn as lines too)

RC = {
    "font.size": 8.0,
    "axes.titlesize": 7.5,
    "axes.labelsize": 8.0,
    "xtick.labelsize": 7.5,
    "ytick.labelsize": 7.5,
    "legend.fontsize": 7.0,
    "legend.framealpha": 0.85,
    "figure.titlesize": 10.0,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "grid.linewidth": 0.5,
    "lines.linewidth": 1.1,
    "lines.markersize": 3.5,
    "axes.prop_cycle": cycler(color=list(COLORS)),
    "axes.formatter.useoffset": False,        # no "+1.2e1" offsets on a constant signal's axis
    "axes.formatter.limits": (-3, 4),
    "axes.formatter.use_mathtext": True,
    "mathtext.default": "it",
    "image.cmap": "viridis",
    "savefig.dpi": DPI,
    "figure.dpi": 100,
}

F = TypeVar("F", bound=Callable[..., Any])


def styled(fn: F) -> F:
    """Decorator: run a figure function inside ``matplotlib.rc_context(RC)`` (marks it ``__styled__``).

    Parameters
    ----------
    fn : callable
        A figure function.

    Returns
    -------
    callable
        ``fn`` drawing in the style.
    """
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with mpl.rc_context(RC):
            return fn(*args, **kwargs)
    wrapper.__styled__ = True
    return wrapper  # type: ignore[return-value]


def new_figure(width_in: float, height_in: float, layout: str | None = "constrained") -> Figure:
    """A Figure on the Agg canvas, ``width_in`` x ``height_in`` [in] clamped to :data:`MAX_SIZE_IN`.

    Parameters
    ----------
    width_in, height_in : float
        Requested size [in].
    layout : str or None
        Matplotlib layout engine ("constrained" by default).

    Returns
    -------
    matplotlib.figure.Figure
        The figure.
    """
    fig = Figure(figsize=(min(width_in, MAX_SIZE_IN[0]), min(height_in, MAX_SIZE_IN[1])), layout=layout)
    FigureCanvasAgg(fig)
    return fig


def suptitle(fig: Figure, text: str, **kwargs) -> None:
    """The figure title, each line wrapped to the figure's width (a long title is not cut at the edges).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    text : str
        The title; "\\n" separates lines.
    **kwargs
        Passed to ``Figure.suptitle`` (e.g. ``fontsize``).
    """
    size = kwargs.get("fontsize", mpl.rcParams["figure.titlesize"])
    size = size if isinstance(size, (int, float)) else 10.0
    width = max(30, int(fig.get_figwidth() * 72 / (0.6 * size)))
    fig.suptitle("\n".join(textwrap.fill(line, width, break_on_hyphens=False) for line in text.split("\n")), **kwargs)


_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def safe_name(text: str) -> str:
    """A file-name part from any text: runs of characters other than letters, digits, ".", "_", "-" become
    "-" ("filler_saturation+coil_heating" -> "filler_saturation-coil_heating"); never empty.

    Parameters
    ----------
    text : str
        Any text.

    Returns
    -------
    str
        Letters, digits, ".", "_" and "-" only, not starting with "." or "-".
    """
    out = _UNSAFE.sub("-", text).strip("-.")
    return out or "figure"


def save(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` to ``path`` (its name made safe, folders created) at :data:`DPI`; returns the path.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or Path
        Where to write; the suffix gives the format.

    Returns
    -------
    Path
        The written file (its name made safe).
    """
    p = Path(path)
    p = p.with_name(safe_name(p.stem) + p.suffix)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p, dpi=DPI)
    return p


# ------------------------------------------------------------------------------------------ units
UNIT_SYMBOLS = {"Ohm": "Ω", "ohm": "Ω", "um": "µm", "us": "µs", "deg": "°", "pct": "%", "degC": "°C"}
_SUP = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")
_TERM = re.compile(r"([A-Za-zµΩ°%]+)(-?\d+)?")


def _term(t: str) -> str:
    m = _TERM.fullmatch(t)
    if not m:
        return t
    sym, exp = m.groups()
    return UNIT_SYMBOLS.get(sym, sym) + ((exp or "").translate(_SUP) if exp not in (None, "1") else "")


def unit_text(unit: str) -> str:
    """A unit string as the specs write it, typeset: "." -> "·", exponents raised, Ohm -> Ω, um -> µm,
    "1" (dimensionless) -> "–" ("N.m/T2" -> "N·m/T²", "1/T2" -> "1/T²", "N/m3" -> "N/m³").

    Parameters
    ----------
    unit : str
        Unit string ("N.m/T2", "Ohm", "1").

    Returns
    -------
    str
        The unit for print.
    """
    unit = unit.strip()
    if unit in ("", "1", "-"):
        return "–"
    num, slash, den = unit.partition("/")
    head = "·".join(_term(t) for t in num.split(".")) if num else "1"
    return head + ("/" + "·".join(_term(t) for t in den.split(".")) if slash else "")


#: smaller units of a unit, with their factor: a value v in the unit is v * factor in the smaller one
SMALLER_UNITS = {"N": (("mN", 1e3), ("µN", 1e6)), "mm": (("µm", 1e3),), "m": (("mm", 1e3), ("µm", 1e6)),
                 "A": (("mA", 1e3),), "V": (("mV", 1e3),), "s": (("ms", 1e3),)}


def prefixed_unit(unit: str, values) -> tuple[str, float]:
    """(unit, factor) to show ``values`` (in ``unit``) without an axis offset: the first smaller unit of
    :data:`SMALLER_UNITS` in which the largest magnitude reaches 1, else the smallest listed; ``unit`` and 1
    when that magnitude is 0.1 or more, 0, or NaN, or the unit has no smaller one (0.004 N -> ("mN", 1000)).

    Parameters
    ----------
    unit : str
        Unit of ``values``.
    values : array_like
        The values to show.

    Returns
    -------
    (str, float)
        The unit to show and the factor to multiply ``values`` by.
    """
    v = np.asarray(values, dtype=float)
    peak = float(np.nanmax(np.abs(v))) if v.size and np.isfinite(v).any() else float("nan")
    if not (0.0 < peak < 0.1) or unit not in SMALLER_UNITS:
        return unit, 1.0
    for smaller, factor in SMALLER_UNITS[unit]:
        if peak * factor >= 1.0:
            return smaller, factor
    return SMALLER_UNITS[unit][-1]


def label(quantity: str, unit: str | None) -> str:
    """An axis label: quantity and unit in parentheses ("Displacement $x$", "mm" -> "Displacement $x$ (mm)");
    dimensionless (unit "1" or "") -> "(–)"; ``None``: no unit known (the quantity alone).

    Parameters
    ----------
    quantity : str
        Quantity and symbol (mathtext allowed).
    unit : str or None
        Unit string as the specs write it.

    Returns
    -------
    str
        The label.
    """
    if unit is None:
        return quantity
    return f"{quantity} ({unit_text(unit)})"


# ------------------------------------------------------------------------------------------ keys
#: quantity names of the project's column and JSON keys (the part before the unit)
QUANTITY_NAMES = {
    "time": "Time $t$", "t": "Time $t$",
    "voltage": "Voltage $V$", "V": "Voltage $V$",
    "current": "Current $I$", "I": "Current $I$",
    "displacement": "Displacement $x$", "x": "Displacement $x$", "x_ref": "Set-point $x_\\mathrm{ref}$",
    "force": "Force $F$", "F": "Force $F$", "blocked_force": "Blocked force $F_\\mathrm{b}$",
    "field": "Field $B$", "B": "Field $B$",
    "gap": "Gap $r_0$", "r0": "Gap $r_0$",
    "power": "Coil power $P$", "energy": "Energy $E$",
    "stroke": "Stroke", "static_stroke": "Static stroke",
    "settling": "2 % settling time", "ste": "settling-time error", "rmse": "RMSE",
    "wt": "Filler fraction", "diameter": "Diameter $D$", "D": "Diameter $D$",
    "bandwidth": "Bandwidth", "margin": "Margin", "probability": "Probability",
    "pull_in_current": "Pull-in current",
}
_UNIT_TOKENS = {"s", "ms", "us", "mm", "um", "m", "N", "V", "A", "mA", "W", "Hz", "T", "K", "H", "Ohm", "kg", "J",
                "deg", "rad", "pct"}
_TEST = re.compile(r"(T\d+)_(.+)")


def _is_unit_token(tok: str) -> bool:
    """A unit symbol of a key, with an optional power ("m3", "T2") or "1" (dimensionless)."""
    m = re.fullmatch(r"([A-Za-z]+)(\d*)", tok)
    return tok == "1" or (m is not None and m.group(1) in _UNIT_TOKENS)


def split_key(key: str) -> tuple[str, str | None]:
    """(name, unit) of a key with its unit spelled as a suffix: "time_s" -> ("time", "s"),
    "Em_N_m_per_T2" -> ("Em", "N.m/T2"), "ksat_per_T2" -> ("ksat", "1/T2"), "wt_pct" -> ("wt", "wt%"),
    no recognised unit -> (key, None). The unit is the last token or, with "per", the quotient around the last
    "per", its numerator extended left over unit tokens; the name keeps at least one token. A bare product is
    read as its last factor ("tau_s_s" -> ("tau_s", "s")), as the project's keys spell products only in a
    quotient ("C_N_s_per_m").

    Parameters
    ----------
    key : str
        Column or JSON key.

    Returns
    -------
    (str, str or None)
        Name and unit string (None: no unit found).
    """
    toks = key.split("_")
    if len(toks) < 2 or not _is_unit_token(toks[-1]):
        return key, None
    i = len(toks) - 1
    if "per" in toks[1:]:
        j = len(toks) - 1 - toks[::-1].index("per")            # the last "per"
        if all(_is_unit_token(t) for t in toks[j + 1:]):
            i = j
            while i - 1 >= 1 and _is_unit_token(toks[i - 1]):
                i -= 1
    unit_toks = toks[i:]
    name = "_".join(toks[:i])
    if "per" in unit_toks:
        k = unit_toks.index("per")
        num, den = unit_toks[:k], unit_toks[k + 1:]
        unit = (".".join(num) if num else "1") + "/" + ".".join(den)
    else:
        unit = ".".join(unit_toks)
    if unit == "pct":
        unit = "wt%" if name == "wt" else "%"
    return name, unit


def key_label(key: str, names: dict | None = None) -> str:
    """An axis label from a column or JSON key: quantity name (:data:`QUANTITY_NAMES`, or ``names``, or the
    name with spaces for "_") and unit in parentheses ("time_s" -> "Time $t$ (s)", "T3_ste_s" -> "T3
    settling-time error (s)", "Em_N_m_per_T2" -> "Em (N·m/T²)"). A test prefix ("T3_") leads the label.

    Parameters
    ----------
    key : str
        Column or JSON key ("time_s", "T3_ste_s").
    names : dict or None
        Extra quantity names by key name.

    Returns
    -------
    str
        The label.
    """
    table = {**QUANTITY_NAMES, **(names or {})}
    test = ""
    m = _TEST.fullmatch(key)
    if m and m.group(2):
        test, key = m.group(1) + " ", m.group(2)
    name, unit = split_key(key)
    text = table.get(name, name.replace("_", " "))
    if test and text[:1].isupper() and not text[1:2].isupper():
        text = text[0].lower() + text[1:]
    return label(test + text, unit)


def envelope(x, y, max_points: int = 4000) -> tuple[np.ndarray, np.ndarray]:
    """A long trace reduced for drawing to at most about ``max_points`` points that keep its envelope: the
    record cut into ``max_points // 2`` consecutive buckets, each drawn as its minimum and its maximum in the
    order they occur. A line through them covers the same band as the whole trace (a residual's noise looks as
    it is); shorter traces are returned as they are. Saves most of the drawing time of 10-20 kHz records.

    Parameters
    ----------
    x, y : array_like
        The trace (same length).
    max_points : int
        The most points drawn.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        The points to draw.

    Examples
    --------
    >>> xs, ys = envelope(np.arange(10.0), np.array([0, 5, 1, 1, -3, 1, 1, 1, 2, 1.0]), max_points=4)
    >>> xs.tolist(), ys.tolist()
    ([1.0, 4.0, 5.0, 8.0], [5.0, -3.0, 1.0, 2.0])
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    n_buckets = max(1, max_points // 2)
    if y.size <= max_points:
        return x, y
    edges = np.linspace(0, y.size, n_buckets + 1).astype(int)
    idx = []
    for a, b in zip(edges[:-1], edges[1:]):
        seg = y[a:b]
        i, j = a + int(np.argmin(seg)), a + int(np.argmax(seg))
        idx += [min(i, j), max(i, j)] if i != j else [i]
    idx = np.asarray(idx)
    return x[idx], y[idx]
