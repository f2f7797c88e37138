"""Paper-style result tables (Tables 3, 4 and 5) as Markdown and CSV.

Input: a list of per-sample, per-test result records (plain dicts), e.g.::

    {"sample": "W20-D45", "wt_pct": 20, "diameter_mm": 45, "test": "T3",
     "rmse_mm": 0.042, "ste_s": 0.33}

Required keys: ``sample`` (id), ``wt_pct`` (filler fraction, wt%),
``diameter_mm`` (diaphragm diameter, mm) and ``test`` ("T1".."T8"). Metric keys
(any subset; missing or ``None`` = not available):

========================  ==============================================
``rmse_mm``               RMSE of a displacement, mm (T1-T6)
``rmse_N``                RMSE of a blocked force, N (T7, T8)
``ste_s``                 2 % settling-time error, s (T2-T5)
``amplitude_ratio``       A_sim / A_meas, - (T6)
``phase_shift_rad``       phi_sim - phi_meas, rad; negative = simulation lags (T6)
========================  ==============================================

Tables
------
* Table 3 (identification, T3/T5: RMSE and STE) and Table 4 (validation: T1
  RMSE, T2/T4 RMSE and STE, T6 amplitude ratio and phase shift, T7 RMSE) give,
  for each diameter, "mean (std)" across the filler fractions (by default the
  identification samples 10, 20 and 30 wt%), std being the sample standard
  deviation (ddof=1) as in the paper. One value: "value (n/a)". No value: "–".
  Non-finite values (e.g. a STE of a response that never settled) are left out
  of mean and std and the cell is flagged with "†".
  The paper labels the T7 RMSE in mm; it is a force RMSE and is given in N here.
* Table 5: one row per sample (the unseen 15 and 25 wt% samples), every test.
* Long table: one row per record with all its fields.

CSV files have one header row whose column names carry units
(``T3_rmse_mm_mean``, ``T6_phase_shift_rad_std``, ...); floats are written with
full precision (``repr``), missing values as empty fields.
"""
from __future__ import annotations

import csv
import math
import numbers
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "METRICS",
    "TABLE3_COLUMNS",
    "TABLE4_COLUMNS",
    "TABLE5_COLUMNS",
    "IDENTIFICATION_WT_PCT",
    "long_table_markdown",
    "table3_markdown",
    "table4_markdown",
    "table5_markdown",
    "write_tables",
]

DASH = "–"          # missing entry (en dash)
NONFINITE_MARK = "†"

# metric key -> header label (with unit)
METRICS: dict[str, str] = {
    "rmse_mm": "RMSE (mm)",
    "rmse_N": "RMSE (N)",
    "ste_s": "STE (s)",
    "amplitude_ratio": "Amplitude ratio (-)",
    "phase_shift_rad": "Phase shift (rad)",
}

# labels of other per-record fields shown in the long table (formatted like metrics)
EXTRA_LABELS: dict[str, str] = {
    "current_rmse_A": "Current RMSE (A)",
    "ts_meas_s": "Ts measured (s)",
    "ts_sim_s": "Ts simulated (s)",
    "smooth_window_s": "Smoothing window (s)",
}

TABLE3_COLUMNS: tuple[tuple[str, str], ...] = (
    ("T3", "rmse_mm"), ("T3", "ste_s"), ("T5", "rmse_mm"), ("T5", "ste_s"),
)
TABLE4_COLUMNS: tuple[tuple[str, str], ...] = (
    ("T1", "rmse_mm"),
    ("T2", "rmse_mm"), ("T2", "ste_s"),
    ("T4", "rmse_mm"), ("T4", "ste_s"),
    ("T6", "amplitude_ratio"), ("T6", "phase_shift_rad"),
    ("T7", "rmse_N"),
)
TABLE5_COLUMNS: tuple[tuple[str, str], ...] = (
    ("T1", "rmse_mm"),
    ("T2", "rmse_mm"), ("T2", "ste_s"),
    ("T3", "rmse_mm"), ("T3", "ste_s"),
    ("T4", "rmse_mm"), ("T4", "ste_s"),
    ("T5", "rmse_mm"), ("T5", "ste_s"),
    ("T6", "amplitude_ratio"), ("T6", "phase_shift_rad"),
    ("T7", "rmse_N"),
)
IDENTIFICATION_WT_PCT: tuple[float, ...] = (10, 20, 30)  # samples of Tables 3 and 4

_REQUIRED = ("sample", "wt_pct", "diameter_mm", "test")
_TEST_ORDER = {f"T{i}": i for i in range(1, 9)}


# --------------------------------------------------------------------------- helpers
def _check_records(records: Iterable[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    recs = list(records)
    seen: set[tuple[str, str]] = set()
    for i, r in enumerate(recs):
        if not isinstance(r, Mapping):
            raise ValueError(f"records[{i}]: expected a dict, got {type(r).__name__}")
        missing = [k for k in _REQUIRED if k not in r or r[k] is None]
        if missing:
            raise ValueError(f"records[{i}]: missing key(s) {', '.join(missing)}")
        key = (str(r["sample"]), str(r["test"]))
        if key in seen:
            raise ValueError(f"records[{i}]: duplicate record for sample {key[0]} test {key[1]}")
        seen.add(key)
    return recs


def _num(v: Any) -> float | None:
    """A record value as float, None if absent."""
    if v is None or v == "":
        return None
    return float(v)


def _fmt(v: float | None, digits: int) -> str:
    if v is None:
        return DASH
    if not math.isfinite(v):
        return "NaN" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    if v != 0 and abs(v) < 10.0 ** (1 - digits):
        return f"{v:.{max(digits - 1, 1)}e}"   # small values (forces in N) keep their significant digits
    return f"{v:.{digits}f}"


def _fmt_plain(v: Any) -> str:
    """Number formatting for a compact label (wt% and diameter): 20.0 -> '20'."""
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    return f"{f:g}"


def _sort_key(r: Mapping[str, Any]) -> tuple:
    return (float(r["diameter_mm"]), float(r["wt_pct"]), str(r["sample"]),
            _TEST_ORDER.get(str(r["test"]), 99), str(r["test"]))


def _in_set(value: Any, allowed: Sequence[float] | None) -> bool:
    return allowed is None or any(abs(float(value) - float(a)) < 1e-9 for a in allowed)


def _stats(values: list[float]) -> dict[str, Any]:
    """mean, sample std (ddof=1), n (finite values), n_nonfinite."""
    finite = [v for v in values if math.isfinite(v)]
    n = len(finite)
    mean = sum(finite) / n if n else None
    std = None
    if n >= 2:
        std = math.sqrt(sum((v - mean) ** 2 for v in finite) / (n - 1))
    return {"mean": mean, "std": std, "n": n, "n_nonfinite": len(values) - n}


def _cell(st: dict[str, Any], digits: int) -> str:
    if st["n"] == 0 and st["n_nonfinite"] == 0:
        return DASH
    if st["n"] == 0:
        return "NaN" + NONFINITE_MARK
    std = "n/a" if st["std"] is None else _fmt(st["std"], digits)
    mark = NONFINITE_MARK if st["n_nonfinite"] else ""
    return f"{_fmt(st['mean'], digits)} ({std}){mark}"


def _header(test: str, key: str) -> str:
    return f"{test} {METRICS.get(key, key)}"


def _md_table(header: list[str], rows: list[list[str]], align: list[str]) -> str:
    sep = [{"l": ":---", "r": "---:", "c": ":---:"}[a] for a in align]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(sep) + " |"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def _summary(records, columns, wt_pct):
    """Per-diameter statistics: list of (diameter, n_samples, {(test, key): stats})."""
    recs = [r for r in _check_records(records) if _in_set(r["wt_pct"], wt_pct)]
    diameters = sorted({float(r["diameter_mm"]) for r in recs})
    out = []
    for d in diameters:
        rd = [r for r in recs if abs(float(r["diameter_mm"]) - d) < 1e-9]
        cols = {}
        for test, key in columns:
            vals = [_num(r.get(key)) for r in rd if str(r["test"]) == test]
            cols[(test, key)] = _stats([v for v in vals if v is not None])
        out.append((d, len({str(r["sample"]) for r in rd}), cols))
    return out


def _summary_markdown(records, columns, wt_pct, digits, caption) -> str:
    summary = _summary(records, columns, wt_pct)
    header = ["Diameter (mm)"] + [_header(t, k) for t, k in columns]
    rows = [[_fmt_plain(d)] + [_cell(cols[c], digits) for c in columns]
            for d, _, cols in summary]
    parts = [caption, "", _md_table(header, rows, ["r"] * len(header))]
    if not rows:
        parts.append("\n(no records)")
    notes = ["Cells: mean (sample std, ddof=1) across filler fractions; "
             "\"(n/a)\": a single value; \"–\": not available."]
    if any(st["n_nonfinite"] for _, _, cols in summary for st in cols.values()):
        notes.append(f"{NONFINITE_MARK} non-finite values (e.g. a response that never "
                     "settled) left out of mean and std.")
    parts.append("")
    parts.extend(notes)
    return "\n".join(parts) + "\n"


def _wt_label(wt_pct: Sequence[float] | None) -> str:
    if wt_pct is None:
        return "all"
    return ", ".join(_fmt_plain(w) for w in wt_pct) + " wt%"


# --------------------------------------------------------------------------- public
def _diameter_table(records, columns, caption: str, wt_pct, digits: int) -> str:
    """Tables 3 and 4 (``columns``), the caption's "{samples}" replaced by the filler fractions shown."""
    return _summary_markdown(records, columns, wt_pct, digits, caption.format(samples=_wt_label(wt_pct)))


def table3_markdown(records: Iterable[Mapping[str, Any]],
                    wt_pct: Sequence[float] | None = IDENTIFICATION_WT_PCT,
                    digits: int = 4) -> str:
    """Table 3 layout: identification results (T3, T5: RMSE [mm], STE [s]) per diameter.

    Parameters
    ----------
    records : iterable of mapping
        Result records (module docstring: ``sample``, ``wt_pct``, ``diameter_mm``, ``test``, metrics).
    wt_pct : sequence of float or None
        Filler fractions [wt%] of the samples summarized (None: all).
    digits : int
        Decimals of the numbers.

    Returns
    -------
    str
        Markdown: caption, one row per diameter [mm], each cell "mean (std)" across the samples.

    Raises
    ------
    ValueError
        A record lacks a required key or repeats a (sample, test) pair.
    """
    return _diameter_table(records, TABLE3_COLUMNS, "Table 3. Multi-objective optimization (identification) "
                           "results, samples {samples}.", wt_pct, digits)


def table4_markdown(records: Iterable[Mapping[str, Any]],
                    wt_pct: Sequence[float] | None = IDENTIFICATION_WT_PCT,
                    digits: int = 4) -> str:
    """Table 4 layout: validation results per diameter.

    Columns: T1 RMSE [mm]; T2, T4 RMSE [mm] and STE [s]; T6 amplitude ratio [-] and phase shift [rad];
    T7 blocked-force RMSE [N]. Parameters, return value and errors as :func:`table3_markdown`.
    """
    return _diameter_table(records, TABLE4_COLUMNS, "Table 4. Model validation results, samples {samples} "
                           "(T7 is a blocked-force RMSE, in N).", wt_pct, digits)


def _table5_rows(records, samples):
    recs = _check_records(records)
    by_sample: dict[str, list[Mapping[str, Any]]] = {}
    for r in recs:
        by_sample.setdefault(str(r["sample"]), []).append(r)
    rows = []
    for s in samples:
        if str(s) not in by_sample:
            raise ValueError(f"samples: no record for sample {s!r}")
        rs = by_sample[str(s)]
        values = {}
        for test, key in TABLE5_COLUMNS:
            vals = [_num(r.get(key)) for r in rs if str(r["test"]) == test]
            values[(test, key)] = vals[0] if vals else None
        rows.append((str(s), rs[0]["diameter_mm"], rs[0]["wt_pct"], values))
    return rows


def table5_markdown(records: Iterable[Mapping[str, Any]], samples: Sequence[str],
                    digits: int = 4) -> str:
    """Table 5 layout: one row per sample, every test's metrics (units in the headers).

    Parameters
    ----------
    records : iterable of mapping
        Result records (module docstring).
    samples : sequence of str
        Sample ids, one row each in this order (e.g. the unseen 15 and 25 wt% samples).
    digits : int
        Decimals of the numbers.

    Returns
    -------
    str
        Markdown: caption and table.

    Raises
    ------
    ValueError
        A sample id has no record, or a record is invalid.
    """
    rows = _table5_rows(records, samples)
    header = ["Sample", "Diameter (mm)", "Filler (wt%)"] + [_header(t, k) for t, k in TABLE5_COLUMNS]
    body = [[s, _fmt_plain(d), _fmt_plain(w)] + [_fmt(v[c], digits) for c in TABLE5_COLUMNS]
            for s, d, w, v in rows]
    caption = "Table 5. Simulation results for unseen samples (T7 is a blocked-force RMSE, in N)."
    return (caption + "\n\n" + _md_table(header, body, ["l", "r", "r"] + ["r"] * len(TABLE5_COLUMNS))
            + "\n\n\"–\": not available.\n")


def _long_columns(recs) -> list[str]:
    extra = sorted({k for r in recs for k in r} - set(_REQUIRED) - set(METRICS))
    present = [k for k in METRICS if any(k in r for r in recs)]
    return list(_REQUIRED) + present + extra


def long_table_markdown(records: Iterable[Mapping[str, Any]], digits: int = 4) -> str:
    """Per-sample long table: one row per record, sorted by diameter [mm], filler fraction [wt%], test.

    Parameters
    ----------
    records : iterable of mapping
        Result records (module docstring); extra fields get their own columns.
    digits : int
        Decimals of metrics; significant digits of other floats.

    Returns
    -------
    str
        Markdown: caption and table.
    """
    recs = sorted(_check_records(records), key=_sort_key)
    cols = _long_columns(recs)
    header = [{"sample": "Sample", "wt_pct": "Filler (wt%)", "diameter_mm": "Diameter (mm)",
               "test": "Test"}.get(c, METRICS.get(c, EXTRA_LABELS.get(c, c))) for c in cols]
    body = []
    for r in recs:
        row = []
        for c in cols:
            v = r.get(c)
            if c in ("wt_pct", "diameter_mm"):
                row.append(_fmt_plain(v))
            elif c in METRICS or c in EXTRA_LABELS:
                row.append(_fmt(_num(v), digits))
            elif isinstance(v, float):
                row.append(f"{v:.{digits}g}")
            else:
                row.append(DASH if v is None else str(v))
        body.append(row)
    align = ["l" if c in ("sample", "test") else "r" for c in cols]
    return "Per-sample results.\n\n" + _md_table(header, body, align) + "\n"


# --------------------------------------------------------------------------- CSV
def _csv_value(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, numbers.Integral):
        return int(v)
    if isinstance(v, numbers.Real):
        return repr(float(v))  # shortest round-tripping text, also for numpy scalars
    return v


def _write_csv(path: Path, header: list[str], rows: list[list[Any]]) -> Path:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([_csv_value(v) for v in r])
    return path


def _summary_csv(path, records, columns, wt_pct) -> Path:
    header = ["diameter_mm", "n_samples"]
    for t, k in columns:
        header += [f"{t}_{k}_mean", f"{t}_{k}_std", f"{t}_{k}_n", f"{t}_{k}_n_nonfinite"]
    rows = []
    for d, n, cols in _summary(records, columns, wt_pct):
        row: list[Any] = [d, n]
        for c in columns:
            st = cols[c]
            row += [st["mean"], st["std"], st["n"], st["n_nonfinite"]]
        rows.append(row)
    return _write_csv(path, header, rows)


def write_tables(records: Iterable[Mapping[str, Any]], out_dir: str | Path, stem: str,
                 table5_samples: Sequence[str] | None = None,
                 wt_pct: Sequence[float] | None = IDENTIFICATION_WT_PCT,
                 digits: int = 4, skipped: Mapping[str, str] | None = None,
                 summary_samples: Sequence[str] | None = None) -> list[Path]:
    """Write all tables as CSV and Markdown.

    Parameters
    ----------
    records : iterable of mapping
        Result records (module docstring).
    out_dir : str or Path
        Folder, created if needed, for ``<stem>_long.{csv,md}``, ``<stem>_table3.{csv,md}``,
        ``<stem>_table4.{csv,md}`` and, if there are samples for it, ``<stem>_table5.{csv,md}``.
    stem : str
        File-name stem.
    table5_samples : sequence of str or None
        Samples of Table 5 (None: those whose filler fraction is not in ``wt_pct``, i.e. the unseen
        samples, ordered by diameter and filler fraction).
    wt_pct : sequence of float or None
        Filler fractions [wt%] summarized in Tables 3 and 4 (None: all). A dataset none of whose samples has
        one of them (another lab's fractions) has every sample outside ``table5_samples`` summarized instead:
        Tables 3 and 4 are never written empty when there are records.
    digits : int
        Decimals in the Markdown tables (CSV files keep full precision).
    skipped : mapping of str to str or None
        Samples left out for incomplete data, {id: reason}: listed under every Markdown table.
    summary_samples : sequence of str or None
        The samples summarized in Tables 3 and 4 (e.g. the identified ones), overriding ``wt_pct`` for them.

    Returns
    -------
    list of Path
        The written files.
    """
    recs = sorted(_check_records(records), key=_sort_key)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []

    note = ""
    if skipped:
        note = ("\n**Skipped samples** (incomplete data, not identified, not in these tables):\n\n"
                + "".join(f"- {sid}: {why}\n" for sid, why in skipped.items()))

    def md(name: str, text: str) -> None:
        p = out / f"{stem}_{name}.md"
        p.write_text(text + note, encoding="utf-8")
        paths.append(p)

    # long table
    cols = _long_columns(recs)
    paths.append(_write_csv(out / f"{stem}_long.csv", cols, [[r.get(c) for c in cols] for r in recs]))
    md("long", long_table_markdown(recs, digits))
    # tables 3 and 4
    recs34, wt34 = recs, wt_pct
    if summary_samples is None and not any(_in_set(r["wt_pct"], wt_pct) for r in recs):
        summary_samples = sorted({str(r["sample"]) for r in recs} - set(map(str, table5_samples or ())))
    if summary_samples is not None:
        keep = set(map(str, summary_samples))
        recs34 = [r for r in recs if str(r["sample"]) in keep]
        wt34 = sorted({float(r["wt_pct"]) for r in recs34})
    paths.append(_summary_csv(out / f"{stem}_table3.csv", recs34, TABLE3_COLUMNS, wt34))
    md("table3", table3_markdown(recs34, wt34, digits))
    paths.append(_summary_csv(out / f"{stem}_table4.csv", recs34, TABLE4_COLUMNS, wt34))
    md("table4", table4_markdown(recs34, wt34, digits))
    # table 5
    if table5_samples is None:
        table5_samples = []
        for r in recs:
            if wt_pct is not None and not _in_set(r["wt_pct"], wt_pct) \
                    and str(r["sample"]) not in table5_samples:
                table5_samples.append(str(r["sample"]))
    if table5_samples:
        rows5 = _table5_rows(recs, table5_samples)
        header = ["sample", "diameter_mm", "wt_pct"] + [f"{t}_{k}" for t, k in TABLE5_COLUMNS]
        paths.append(_write_csv(out / f"{stem}_table5.csv", header,
                                [[s, d, w] + [v[c] for c in TABLE5_COLUMNS] for s, d, w, v in rows5]))
        md("table5", table5_markdown(recs, table5_samples, digits))
    return paths
