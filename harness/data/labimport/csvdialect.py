"""Delimited text tables in any common dialect (CSV, TSV, whitespace, decimal comma, Excel exports).

Handled: separators ``,`` ``;`` tab or runs of whitespace; ``.`` or ``,`` as decimal mark; a
UTF-8 byte-order mark; LF, CRLF or CR line ends; quoted fields (``"1,5"``); comment lines
(starting with ``#``, ``%`` or ``//``) and blank lines anywhere; preamble lines before the header
(anything above the header row); trailing empty columns (``1;2;;`` as Excel writes them); an
optional units row under the header (``s;mA;µm``). Without a header row columns are addressed by
number.

Detection: every (separator, decimal mark) pair is tried on every line; the pair under which the
most lines are rows of at least two numbers of one common width wins; ``csv.Sniffer``'s separator
breaks ties. The header is the last non-numeric line above the first such row. Every line after
the header must then be a complete row of numbers: a bad cell is an error naming its line and
column. Ambiguities are errors, never guesses: ``,`` used both as separator and decimal mark
(unquoted), or a decimal comma that could be a thousands separator (``1,250`` with no other comma
cell), unless the mapping says which (``csv.delimiter``, ``csv.decimal``).
"""
from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.data.labimport.errors import LabImportError
from harness.data.labimport.table import Channel, Table
from harness.data.labimport.units import quantity_of_unit

__all__ = ["TextOptions", "read_text_table", "decode_bytes", "physical_lines", "DELIMITERS"]

DELIMITERS = {",": ",", ";": ";", "tab": "\t", "\t": "\t", "whitespace": "ws", "ws": "ws", " ": "ws"}
_COMMENT = ("#", "%", "//")
_NUM_DOT = re.compile(r"^[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?$")
_NUM_COMMA = re.compile(r"^[+-]?(?:\d+,?\d*|,\d+)(?:[eE][+-]?\d+)?$")
_THOUSANDS = re.compile(r"^[+-]?[1-9]\d{0,2}(?:,\d{3})+$")
_WS_TOKEN = re.compile(r'"([^"]*)"|(\S+)')
_LINE_SPLIT = re.compile(r"\r\n|\n|\r")
_PROBE_LINES = 2000


@dataclass(frozen=True)
class TextOptions:
    """Overrides of the detection (None = detect). ``delimiter``: ``","``, ``";"``, ``"tab"`` or
    ``"whitespace"``; ``decimal``: ``"."`` or ``","``; ``header_line``: 1-based physical line of
    the header row (0 = no header row); ``encoding``: text encoding (default UTF-8 with or without
    BOM, falling back to cp1252)."""
    delimiter: str | None = None
    decimal: str | None = None
    header_line: int | None = None
    encoding: str | None = None


def decode_bytes(raw: bytes, encoding: str | None, file) -> str:
    """Text of ``raw``: the given encoding, else UTF-8 (BOM stripped), else cp1252."""
    if encoding:
        try:
            return raw.decode(encoding)
        except (LookupError, UnicodeDecodeError) as e:
            raise LabImportError(f"cannot decode as {encoding}: {e}", file=file) from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("cp1252", errors="replace")


def physical_lines(text: str) -> list[str]:
    """Lines split at LF, CRLF or CR (line i of the list is physical line i + 1)."""
    lines = _LINE_SPLIT.split(text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def _is_comment(line: str) -> bool:
    s = line.lstrip()
    return s.startswith(_COMMENT)


def split_fields(line: str, delim: str) -> list[str]:
    """Fields of one line (quotes removed, cells stripped, trailing empty cells dropped)."""
    if delim == "ws":
        cells = [a if a else b for a, b in _WS_TOKEN.findall(line)]
    else:
        cells = next(csv.reader([line], delimiter=delim, quotechar='"', skipinitialspace=True), [])
        cells = [c.strip() for c in cells]
    while cells and cells[-1] == "":
        cells.pop()
    return cells


def parse_number(cell: str, decimal: str) -> float | None:
    """The number in ``cell`` with decimal mark ``decimal``, or None."""
    if decimal == ",":
        if not _NUM_COMMA.match(cell):
            return None
        return float(cell.replace(",", "."))
    if not _NUM_DOT.match(cell):
        return None
    return float(cell)


def _numeric_row(cells: list[str], decimal: str):
    if len(cells) < 2:
        return None
    vals = [parse_number(c, decimal) for c in cells]
    return None if any(v is None for v in vals) else vals


def _sniffed(lines: list[str]) -> str | None:
    try:
        d = csv.Sniffer().sniff("\n".join(lines[:30]), delimiters=",;\t ").delimiter
    except csv.Error:
        return None
    return "ws" if d == " " else d


def _candidates(opts: TextOptions, file) -> list[tuple[str, str]]:
    if opts.delimiter is not None and opts.delimiter not in DELIMITERS:
        raise LabImportError(f"unknown delimiter {opts.delimiter!r} (use ',', ';', 'tab' or 'whitespace')",
                             file=file, key="csv.delimiter")
    if opts.decimal not in (None, ".", ","):
        raise LabImportError(f"decimal must be '.' or ',', got {opts.decimal!r}", file=file, key="csv.decimal")
    delims = [DELIMITERS[opts.delimiter]] if opts.delimiter is not None else [",", ";", "\t", "ws"]
    decs = [opts.decimal] if opts.decimal is not None else [".", ","]
    return [(d, m) for d in delims for m in decs]


def _score(content, delim, dec):
    """(number of numeric rows of the modal width, that width, index of its first row)."""
    widths = []
    for _, line in content:
        vals = _numeric_row(split_fields(line, delim), dec)
        widths.append(len(vals) if vals is not None else 0)
    w = np.array(widths)
    if not (w >= 2).any():
        return 0, 0, -1
    k = int(np.bincount(w[w >= 2]).argmax())
    first = int(np.nonzero(w == k)[0][0])
    return int((w == k).sum()), k, first


def _is_units_row(cells: list[str]) -> bool:
    units = [c.strip("[]() ") for c in cells if c.strip()]
    return bool(units) and all(quantity_of_unit(u) is not None for u in units)


def read_text_table(path, opts: TextOptions = TextOptions()) -> Table:
    """Read a delimited text file (opened read-only) into a :class:`Table`.

    Parameters
    ----------
    path : path-like
        The file (CSV, TSV, TXT, DAT ...).
    opts : TextOptions
        Overrides of the detected dialect.

    Returns
    -------
    Table
        Channels named by the header (``"Time [s]"`` keeps its unit in the name and in
        ``Channel.unit``) or ``"column 1"`` ... without a header; ``notes`` record the dialect.

    Examples
    --------
    >>> t = read_text_table("run1.csv")                                 # doctest: +SKIP
    >>> t.find("Current").unit                                          # doctest: +SKIP
    'mA'
    """
    from harness.data.labimport.units import split_unit

    file = Path(path)
    with open(file, "rb") as fh:
        raw = fh.read()
    text = decode_bytes(raw, opts.encoding, file)
    lines = physical_lines(text)
    content = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not _is_comment(ln)]
    if not content:
        raise LabImportError("no data: the file is empty or holds only comments", file=file)
    cands = _candidates(opts, file)
    probe = content[:_PROBE_LINES]          # dialect detection looks at the head of long files
    scored = [(_score(probe, d, m), d, m) for d, m in cands]
    best = max(s[0][0] for s in scored)
    if best == 0:
        raise LabImportError("found no rows of numbers (tried separators , ; tab whitespace and decimal marks . ,)",
                             file=file)
    top = [s for s in scored if s[0][0] == best]
    if len(top) > 1:
        sniff = _sniffed([ln for _, ln in content[top[0][0][2]:]])
        top.sort(key=lambda s: (s[1] != sniff, s[2] != ".", [",", ";", "\t", "ws"].index(s[1])))
        # different readings of the same rows must agree, else the file is ambiguous
        (n0, k0, f0), d0, m0 = top[0]
        for (n1, k1, f1), d1, m1 in top[1:]:
            r0 = _numeric_row(split_fields(content[f0][1], d0), m0)
            r1 = _numeric_row(split_fields(content[f1][1], d1), m1)
            if k1 != k0 or f1 != f0 or r0 != r1:
                raise LabImportError(
                    f"the dialect is ambiguous: separator {_show(d0)} with decimal {m0!r} and separator "
                    f"{_show(d1)} with decimal {m1!r} both read the data, differently; set csv.delimiter "
                    f"and csv.decimal in the mapping", file=file, line=content[f0][0])
    (count, width, first), delim, dec = top[0]
    # header row
    names: list[str] | None = None
    units_row: list[str] | None = None
    header_lineno = None
    if opts.header_line is not None:
        if opts.header_line == 0:
            start = 0
        else:
            idx = [j for j, (n, _) in enumerate(content) if n == opts.header_line]
            if not idx:
                raise LabImportError(f"header_line {opts.header_line} is blank, a comment or past the end",
                                     file=file, key="csv.header_line")
            header_lineno = opts.header_line
            names = _header_fields(content[idx[0]][1], delim, width)
            start = idx[0] + 1
    else:
        start = first
        if first > 0:
            header_lineno, hline = content[first - 1]
            names = _header_fields(hline, delim, width)
            if first > 1 and len(names) == width and _is_units_row(names):
                units_row = names
                header_lineno, hline = content[first - 2]
                names = _header_fields(hline, delim, width)
    if names is not None and len(names) != width:
        if delim == "," and len(names) < width:
            raise LabImportError(
                f"ambiguous decimal comma: the header (line {header_lineno}) has {len(names)} columns but the "
                f"data rows have {width} when split at ','; the file seems to use ',' both as the separator and "
                f"as the decimal mark. Export with ';' or tab as separator, or quote the numbers",
                file=file, line=content[first][0])
        raise LabImportError(f"the header (line {header_lineno}) has {len(names)} columns but the data rows have "
                             f"{width} (separator {_show(delim)})", file=file, line=content[first][0])
    # data rows: one csv.reader over all lines, every cell checked by the number pattern (in C via map)
    body = content[start:]
    linenos = [n for n, _ in body]
    all_cells = _split_all([ln for _, ln in body], delim)
    pattern = _NUM_COMMA if dec == "," else _NUM_DOT
    flat = [c for cells in all_cells for c in cells]
    if any(len(cells) != width for cells in all_cells) or not all(map(pattern.match, flat)):
        _raise_first_bad_cell(file, body, all_cells, width, dec, names, header_lineno)
    comma_cells = [c for c in flat if "," in c]
    if dec == "," and opts.decimal is None and comma_cells and all(_THOUSANDS.match(c) for c in comma_cells):
        raise LabImportError(f"ambiguous decimal comma: every cell with a comma ({comma_cells[0]!r} ...) could also "
                             f"be a number with a thousands separator; set csv.decimal in the mapping", file=file)
    if dec == ",":
        flat = [c.replace(",", ".") for c in flat]
    rows = np.array(flat, dtype=float)
    data = rows.reshape(-1, width)
    ln = np.array(linenos)
    chans = []
    for j in range(width):
        name = names[j] if names else f"column {j + 1}"
        unit = split_unit(name)[1] if names else None
        if units_row is not None and units_row[j].strip():
            unit = units_row[j].strip("[]() ")
        chans.append(Channel(name=name, values=data[:, j], unit=unit, column=j + 1, lines=ln))
    return Table(file=file, channels=chans,
                 notes={"delimiter": {"ws": "whitespace", "\t": "tab"}.get(delim, delim), "decimal": dec,
                        "header_line": header_lineno})


def _split_all(lines: list[str], delim: str) -> list[list[str]]:
    """:func:`split_fields` of many lines (one csv.reader for all of them)."""
    if delim == "ws":
        return [split_fields(ln, delim) for ln in lines]
    out = []
    for cells in csv.reader(lines, delimiter=delim, quotechar='"', skipinitialspace=True):
        cells = [c.strip() for c in cells]
        while cells and cells[-1] == "":
            cells.pop()
        out.append(cells)
    return out


def _raise_first_bad_cell(file, body, all_cells, width, dec, names, header_lineno):
    """Raise LabImportError for the first row of the wrong width or cell that is not a number."""
    for (lineno, _), cells in zip(body, all_cells):
        if len(cells) != width:
            raise LabImportError(f"{len(cells)} cells, expected {width}" +
                                 (f" as in the header (line {header_lineno})" if header_lineno else ""),
                                 file=file, line=lineno)
        for j, c in enumerate(cells):
            if parse_number(c, dec) is None:
                why = "empty cell" if c == "" else f"cell {c!r} is not a number"
                if dec == "." and parse_number(c, ",") is not None:
                    why += " (decimal comma in a file read with '.' as decimal mark?)"
                raise LabImportError(why, file=file, line=lineno, column=j + 1,
                                     column_name=names[j] if names else None)
    raise AssertionError("no bad cell found")   # pragma: no cover


def _header_fields(line: str, delim: str, width: int) -> list[str]:
    """Header cells; in whitespace-separated files names may hold single spaces (``Time [s]``)
    when columns are separated by two or more spaces or a tab."""
    cells = split_fields(line, delim)
    if delim == "ws" and len(cells) != width:
        alt = [c.strip().strip('"') for c in re.split(r"\s{2,}|\t", line.strip())]
        if len(alt) == width:
            return alt
    return cells


def _show(d: str) -> str:
    return {"ws": "whitespace", "\t": "tab"}.get(d, repr(d))
