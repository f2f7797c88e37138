"""REFERENCE for the tests only: ``harness/data/csvfile.py`` as it was before the streaming reader
(main at 86c0c91), which held the whole text, a list of its lines and a list of all split rows.
tests/data/test_csv_stream.py checks that the streaming reader gives the same arrays and the same
errors. One deliberate change, marked FIXED below: a decode error names the file's byte offset (a
BOM counted) and the physical line as the parser counts lines (a lone CR breaks a line).

Reading and checking the CSV file of one test of an ``mpc-actuator-data/1`` dataset.

:func:`parse_csv` checks header, units, cells, row counts, time order and gaps, and
raises :class:`~harness.data.format.DataFormatError` naming file, physical line and
column; :func:`build_test` makes the record of a test from its columns.
"""
from __future__ import annotations

import csv
import difflib
import math
import re

import numpy as np

from harness.data.format import COLUMNS, SWEEP_TESTS, DataFormatError
from harness.data.records import GapSweep, TimeSeries

__all__ = ["decode_text", "parse_csv", "build_test"]

_MIN_ROWS_TIME_SERIES = 2
_MIN_ROWS_SWEEP = 1
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?")
_NONFINITE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)
_LINE_SPLIT = re.compile(r"\r\n|\n|\r")


def decode_text(raw: bytes, display) -> str:
    bom = 3 if raw.startswith(b"\xef\xbb\xbf") else 0
    try:
        return raw[bom:].decode("utf-8")
    except UnicodeDecodeError as e:
        # FIXED: was raw[:e.start].count(b"\n") + 1 and e.start, both 3 bytes short after a BOM, and a
        # lone CR not counted as a line break
        start = bom + e.start
        line = len(_LINE_SPLIT.split(raw[bom:start].decode("utf-8")))
        raise DataFormatError(f"not valid UTF-8 text (byte offset {start})", file=display, line=line) from None


def _split_row(line: str) -> list[str]:
    return [c.strip() for c in next(csv.reader([line]))]


def _unit_parts(name: str):
    """('displacement', 'mm') for 'displacement_mm', 'Displacement (mm)', 'displacement [mm]'; else (name, '')."""
    m = re.fullmatch(r"\s*([A-Za-z]+)\s*(?:_\s*|\s+|\[\s*|\(\s*)?([A-Za-z]*)\s*[\])]?\s*", name)
    if not m:
        return name.strip().lower(), ""
    return m.group(1).lower(), m.group(2)


def _column_problem(expected: str, header: list[str], expected_all, display, hline) -> DataFormatError:
    """Explain why ``expected`` is not in the header: wrong unit, misspelt, or just missing."""
    base, unit = expected.rsplit("_", 1)
    others = [(j, h) for j, h in enumerate(header) if h not in expected_all]
    for j, h in others:
        b, u = _unit_parts(h)
        if b == base.lower():
            kw = dict(file=display, line=hline, column=j + 1, column_name=h)
            if not u:
                return DataFormatError(f"column {h!r} has no unit; expected {expected!r} "
                                       f"({base} in {unit})", **kw)
            if u == unit:
                return DataFormatError(f"column {h!r} must be written exactly {expected!r}", **kw)
            if u.lower() == unit.lower() and u != unit:
                return DataFormatError(f"column {h!r}: unit must be written {unit!r} (case matters); "
                                       f"expected {expected!r}", **kw)
            return DataFormatError(f"column {h!r} has unit {u!r} but the format expects {base} in {unit!r}: "
                                   f"convert the values to {unit} and name the column {expected!r}", **kw)
    names = [h for _, h in others]
    close = difflib.get_close_matches(expected, names, n=1, cutoff=0.6)
    if not close:
        low = {h.lower(): h for h in names}
        close = [low[expected.lower()]] if expected.lower() in low else []
    if close:
        j = header.index(close[0])
        return DataFormatError(f"column {close[0]!r} is not a column of this test; did you mean {expected!r}? "
                               f"(required columns: {', '.join(expected_all)})",
                               file=display, line=hline, column=j + 1, column_name=close[0])
    hint = ""
    if len(header) == 1:
        for sep, sname in ((";", "semicolons"), ("\t", "tabs"), (" ", "spaces")):
            if sep in header[0].strip():
                hint = f"; the header seems to be separated by {sname}, the format uses commas"
                break
    return DataFormatError(f"missing required column {expected!r} (required: {', '.join(expected_all)}; "
                           f"found: {', '.join(header) or 'nothing'}){hint}", file=display, line=hline)


def _cell_count_hint(cells: list[str], ncol: int) -> str:
    """Why a data line may have the wrong number of cells (empty when there is no likely reason)."""
    if len(cells) < ncol:
        return ""
    if not any(cells[ncol:]):
        return " (the line ends with a comma: remove the trailing comma, or name the column in the header)"
    if all(_NUMBER.fullmatch(c) for c in cells):   # numbers only, more of them than columns: split decimals
        return " (decimal commas are not allowed; use '.')"
    return ""


def parse_csv(text: str, test: str, display) -> dict[str, np.ndarray]:
    """Parse and check the text of one CSV of ``test``; returns {required column: float64 array}."""
    expected = COLUMNS[test]
    if not text.strip():
        raise DataFormatError("empty file", file=display)
    header = hline = None
    rows: list[tuple[int, list[str]]] = []
    for lineno, line in enumerate(_LINE_SPLIT.split(text), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        if header is None:
            header, hline = _split_row(line), lineno
            if all(_NUMBER.fullmatch(c) or _NONFINITE.fullmatch(c) for c in header):
                raise DataFormatError(f"no header row: this line looks like data; the first non-comment line "
                                      f"must be the header {','.join(expected)}", file=display, line=lineno)
            continue
        rows.append((lineno, _split_row(line) if '"' in line else [c.strip() for c in line.split(",")]))
    if header is None:
        raise DataFormatError(f"no header row (the file has only comments and blank lines); expected "
                              f"{','.join(expected)}", file=display)
    # header: trailing columns without a name (as Excel writes them: "a,b,c,,") are ignored when empty
    ncol = len(header)
    while ncol > 1 and not header[ncol - 1]:
        ncol -= 1
    extra = len(header) - ncol
    header = header[:ncol]
    for j, h in enumerate(header):
        if not h:
            raise DataFormatError("empty column name in the header", file=display, line=hline, column=j + 1)
        if header.index(h) != j:
            raise DataFormatError(f"duplicate column {h!r} (also column {header.index(h) + 1})",
                                  file=display, line=hline, column=j + 1, column_name=h)
    for e in expected:
        if e not in header:
            raise _column_problem(e, header, expected, display, hline)
    idx = {e: header.index(e) for e in expected}
    # rows
    kind = "sweep" if test in SWEEP_TESTS else "time series"
    need = _MIN_ROWS_SWEEP if test in SWEEP_TESTS else _MIN_ROWS_TIME_SERIES
    if len(rows) < need:
        raise DataFormatError(f"too few data rows: {len(rows)} (a {kind} needs at least {need})",
                              file=display)
    for k, (lineno, cells) in enumerate(rows):
        if ncol < len(cells) <= ncol + extra and not any(cells[ncol:]):
            rows[k] = (lineno, cells[:ncol])             # empty cells under the nameless trailing columns
            continue
        if len(cells) != ncol:
            j = next((i for i in range(ncol, len(cells)) if cells[i]), None)
            if extra and j is not None and j < ncol + extra:
                raise DataFormatError(f"value {cells[j]!r} in column {j + 1}, which has no name in the header",
                                      file=display, line=lineno, column=j + 1)
            raise DataFormatError(f"wrong number of cells: {len(cells)}, the header has {ncol}"
                                  f"{_cell_count_hint(cells, ncol)}", file=display, line=lineno)
    out = {}
    for e in expected:
        j = idx[e]
        col = [cells[j] for _, cells in rows]
        if all(map(_NUMBER.fullmatch, col)):
            vals = np.array([float(c) for c in col])
            if np.all(np.isfinite(vals)):
                out[e] = vals
                continue
        for (lineno, _), c in zip(rows, col):      # slow path: find and explain the first bad cell
            kw = dict(file=display, line=lineno, column=j + 1, column_name=e)
            if _NONFINITE.fullmatch(c):
                raise DataFormatError(f"{c!r} is not allowed: values must be finite numbers", **kw)
            if not _NUMBER.fullmatch(c):
                hint = " (decimal commas are not allowed; use '.')" if _DECIMAL_COMMA.fullmatch(c) else ""
                raise DataFormatError(f"non-numeric value {c!r}{hint}" if c else "empty cell", **kw)
            if not math.isfinite(float(c)):
                raise DataFormatError(f"value {c!r} overflows (not a finite double)", **kw)
    lines = [ln for ln, _ in rows]
    if test in SWEEP_TESTS:
        g = out["gap_mm"]
        j = idx["gap_mm"]
        first: dict[float, int] = {}
        for k, (ln, v) in enumerate(zip(lines, g)):
            if v < 0:
                raise DataFormatError(f"negative gap {v:g} mm", file=display, line=ln, column=j + 1,
                                      column_name="gap_mm")
            if v in first:
                raise DataFormatError(f"duplicate gap {v:g} mm on lines {first[v]} and {ln} "
                                      f"(one row per gap)", file=display, line=ln, column=j + 1,
                                      column_name="gap_mm")
            first[v] = ln
    else:
        t = out["time_s"]
        bad = np.nonzero(np.diff(t) <= 0)[0]
        if bad.size:
            k = int(bad[0]) + 1
            raise DataFormatError(f"time not strictly increasing: {float(t[k])!r} s after "
                                  f"{float(t[k - 1])!r} s on line {lines[k - 1]}", file=display, line=lines[k],
                                  column=idx["time_s"] + 1, column_name="time_s")
    return out


def build_test(test: str, cols: dict, entry: dict, file) -> "TimeSeries | GapSweep":
    if test in SWEEP_TESTS:
        return GapSweep(test=test, file=file, gap_mm=cols["gap_mm"], current_A=cols["current_A"],
                        displacement_mm=cols.get("displacement_mm"), force_N=cols.get("force_N"),
                        field_T=entry["field_T"])
    return TimeSeries(test=test, file=file, time_s=cols["time_s"], voltage_V=cols["voltage_V"],
                      current_A=cols["current_A"], displacement_mm=cols.get("displacement_mm"),
                      force_N=cols.get("force_N"), field_T=entry["field_T"], gap_mm=entry["gap_mm"],
                      frequency_hz=entry.get("frequency_hz"))


