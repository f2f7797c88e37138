"""LabVIEW Measurement files (``.lvm``, NI's text format, Writer_Version 1-2).

Layout: a file header (first line ``LabVIEW Measurement``; ``key<sep>value`` lines such as
``Separator`` (``Tab`` or ``Comma``), ``Decimal_Separator`` (``.`` or ``,``), ``X_Columns``
(``No``, ``One`` or ``Multi``)) closed by ``***End_of_Header***``; then one or more segments,
each a channel header (``Channels``, ``Samples``, ``Y_Unit_Label``, ``X_Dimension``, ``X0``,
``Delta_X`` rows with one value per channel) closed by ``***End_of_Header***``, a column-name
row (``X_Value``, channel names, ``Comment``) and rows of numbers.

Time: with ``X_Columns`` One the ``X_Value`` column (unit from ``X_Dimension``, ``Time`` = s);
with Multi the X column before each channel; with No, ``X0 + i * Delta_X`` of the channel. A
channel's unit is its ``Y_Unit_Label`` (or a unit in its name, ``Current [mA]``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.data.labimport.csvdialect import decode_bytes, parse_number, physical_lines
from harness.data.labimport.errors import LabImportError
from harness.data.labimport.table import Channel, Table
from harness.data.labimport.units import split_unit

__all__ = ["read_lvm", "END_OF_HEADER"]

END_OF_HEADER = "***End_of_Header***"
_SEPARATORS = {"tab": "\t", "comma": ","}
_X_DIMENSION_UNITS = {"time": "s"}


def _fields(line: str, sep: str) -> list[str]:
    cells = [c.strip() for c in line.split(sep)]
    while cells and cells[-1] == "":
        cells.pop()
    return cells


def read_lvm(path, segment: int | None = None, encoding: str | None = None) -> Table:
    """Read one data segment of an LVM file (opened read-only) into a :class:`Table`.

    Parameters
    ----------
    path : path-like
        The ``.lvm`` file.
    segment : int, optional
        1-based segment number; required when the file has more than one.
    encoding : str, optional
        Text encoding (default UTF-8, BOM allowed, else cp1252).

    Returns
    -------
    Table
        One channel per data channel (named as in the column-name row, unit from
        ``Y_Unit_Label``), each with ``time_s`` set from its X column or X0/Delta_X, plus
        the X column itself as channel ``X_Value`` when the file has one.

    Examples
    --------
    >>> t = read_lvm("step.lvm")                                        # doctest: +SKIP
    >>> t.find("Current").unit                                          # doctest: +SKIP
    'mA'
    """
    file = Path(path)
    with open(file, "rb") as fh:
        raw = fh.read()
    lines = physical_lines(decode_bytes(raw, encoding, file))
    if not lines or not lines[0].strip().startswith("LabVIEW Measurement"):
        raise LabImportError("not a LabVIEW Measurement file (the first line must be 'LabVIEW Measurement')",
                             file=file, line=1)
    sep = "\t"
    for ln in lines[:40]:
        if ln.startswith("Separator"):
            value = ln[len("Separator"):].strip(" \t,")
            if value.lower() not in _SEPARATORS:
                raise LabImportError(f"unknown Separator {value!r} (LVM knows Tab and Comma)", file=file,
                                     line=lines.index(ln) + 1)
            sep = _SEPARATORS[value.lower()]
            break
    header: dict[str, str] = {}
    i = 1
    while i < len(lines) and not lines[i].strip().startswith(END_OF_HEADER):
        f = _fields(lines[i], sep)
        if f:
            header[f[0]] = f[1] if len(f) > 1 else ""
        i += 1
    if i >= len(lines):
        raise LabImportError(f"no {END_OF_HEADER} line closing the file header", file=file)
    decimal = header.get("Decimal_Separator", ".") or "."
    if decimal not in (".", ","):
        raise LabImportError(f"Decimal_Separator must be '.' or ',', got {decimal!r}", file=file)
    if decimal == "," and sep == ",":
        raise LabImportError("Decimal_Separator ',' with Separator Comma cannot be read unambiguously", file=file)
    x_columns = (header.get("X_Columns") or "One").strip().lower()
    if x_columns not in ("no", "one", "multi"):
        raise LabImportError(f"X_Columns must be No, One or Multi, got {header.get('X_Columns')!r}", file=file)
    segments = _segments(lines, i + 1, sep, file)
    if not segments:
        raise LabImportError("no data segment after the file header", file=file)
    if segment is None:
        if len(segments) > 1:
            raise LabImportError(f"the file has {len(segments)} data segments; choose one with lvm.segment "
                                 f"(1-{len(segments)}) in the mapping", file=file)
        segment = 1
    if not (1 <= segment <= len(segments)):
        raise LabImportError(f"segment {segment} does not exist (the file has {len(segments)})", file=file,
                             key="lvm.segment")
    seg_header, names_lineno, names, rows = segments[segment - 1]
    return _table(file, seg_header, names_lineno, names, rows, sep, decimal, x_columns)


def _segments(lines, i, sep, file):
    """[(channel header {key: [values]}, line of names, names, [(lineno, cells)])]."""
    out = []
    n = len(lines)
    while i < n:
        while i < n and not lines[i].strip():
            i += 1
        if i >= n:
            break
        seg_header: dict[str, list[str]] = {}
        while i < n and not lines[i].strip().startswith(END_OF_HEADER):
            f = _fields(lines[i], sep)
            if f:
                seg_header[f[0]] = f[1:]
            i += 1
        if i >= n:
            raise LabImportError(f"segment header without {END_OF_HEADER}", file=file)
        i += 1
        while i < n and not lines[i].strip():
            i += 1
        if i >= n:
            raise LabImportError("segment without a column-name row", file=file)
        names_lineno, names = i + 1, _fields(lines[i], sep)
        i += 1
        rows = []
        while i < n:
            f = _fields(lines[i], sep)
            if not f:
                i += 1
                continue
            if f[0] == "Channels" or lines[i].strip().startswith(END_OF_HEADER):
                break
            rows.append((i + 1, f))
            i += 1
        out.append((seg_header, names_lineno, names, rows))
    return out


def _table(file, seg_header, names_lineno, names, rows, sep, decimal, x_columns) -> Table:
    cols = [k for k, nm in enumerate(names) if nm != "Comment"]
    width = len(cols)
    data = np.empty((len(rows), width))
    for r, (lineno, cells) in enumerate(rows):
        if len(cells) < width:
            raise LabImportError(f"{len(cells)} cells, expected {width} (column names on line {names_lineno})",
                                 file=file, line=lineno)
        for j in range(width):
            v = parse_number(cells[cols[j]], decimal)
            if v is None:
                raise LabImportError(f"cell {cells[cols[j]]!r} is not a number (Decimal_Separator {decimal!r})",
                                     file=file, line=lineno, column=cols[j] + 1, column_name=names[cols[j]])
            data[r, j] = v
    linenos = np.array([ln for ln, _ in rows])
    per_channel = lambda key, k: (seg_header.get(key) or [])[k] if k < len(seg_header.get(key) or []) else None
    channels, x_vals, x_unit = [], None, None
    ch_index = 0
    for j, k in enumerate(cols):
        nm = names[k]
        if nm == "X_Value":
            x_vals = data[:, j]
            dim = (per_channel("X_Dimension", ch_index) or "Time").strip().lower()
            x_unit = _X_DIMENSION_UNITS.get(dim)
            channels.append(Channel(name="X_Value", values=x_vals, unit=x_unit, column=k + 1, lines=linenos))
            continue
        unit = per_channel("Y_Unit_Label", ch_index) or split_unit(nm)[1]
        if x_columns == "no":
            x0 = per_channel("X0", ch_index)
            dx = per_channel("Delta_X", ch_index)
            if x0 is None or dx is None:
                raise LabImportError(f"X_Columns No but no X0/Delta_X for channel {nm!r}", file=file)
            x0v, dxv = parse_number(x0, decimal), parse_number(dx, decimal)
            if x0v is None or dxv is None:
                raise LabImportError(f"X0/Delta_X of channel {nm!r} are not numbers ({x0!r}, {dx!r})", file=file)
            t = x0v + dxv * np.arange(len(rows))
        else:
            t = None if x_vals is None or x_unit != "s" else x_vals
        channels.append(Channel(name=nm, values=data[:, j], unit=unit or None, column=k + 1, lines=linenos,
                                time_s=t))
        ch_index += 1
    return Table(file=file, channels=channels, notes={"format": "lvm", "X_Columns": x_columns, "decimal": decimal})
