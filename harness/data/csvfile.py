"""Reading and checking the CSV file of one test of an ``mpc-actuator-data/1`` dataset.

:func:`read_csv` (a path or a binary stream) and :func:`parse_csv` (text already in memory)
check header, units, cells, row counts, time order and gaps, and raise
:class:`~harness.data.format.DataFormatError` naming file, physical line and column;
:func:`build_test` makes the record of a test from its columns.

Large files are read in blocks of whole lines (``chunk_size`` bytes, 1 MiB by default) and
never held whole: each block is decoded (UTF-8, a BOM at the start of the file skipped), and
a block of plain numeric lines (ASCII, no quotes, the header's number of commas on every
line) is converted at once by :func:`numpy.loadtxt` (its float parsing accepts, on such
lines, exactly the numbers the per-line check accepts, and gives the same doubles as
``float``). Any other block (comments, blank lines, quoted or non-ASCII cells, a bad cell,
a wrong cell count, a non-finite value) goes through the per-line checks, which give each
problem its physical line and column. Problems are reported in the same order of precedence
as when the whole file is checked at once (an invalid byte anywhere first, then the header,
the row count, cell counts, bad cells column by column, then time order or gaps), so
reading in blocks never changes which error a file gets. Peak memory is the parsed float64
arrays plus one column and one block's temporaries.
"""
from __future__ import annotations

import bisect
import codecs
import csv
import difflib
import math
import os
import re

import numpy as np

from harness.data.format import COLUMNS, DECIMAL_COMMA_HINT, SEPARATOR_HINT, SWEEP_TESTS, DataFormatError
from harness.data.records import GapSweep, TimeSeries

__all__ = ["decode_text", "parse_csv", "read_csv", "build_test"]

_MIN_ROWS_TIME_SERIES = 2
_MIN_ROWS_SWEEP = 1
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?")
_NONFINITE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)
_TAIL_BYTES = np.zeros(256, dtype=bool)   # what an empty cell under a nameless trailing column may hold
_TAIL_BYTES[[ord(","), ord(" "), ord("\t")]] = True


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
                hint = SEPARATOR_HINT.format(sname)
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
        return DECIMAL_COMMA_HINT
    return ""


CHUNK_SIZE = 1 << 20   # bytes (or characters) per block of lines


def _count_lines(text: str) -> int:
    """Line breaks in ``text`` as the reader counts them (``\\r\\n``, ``\\n`` or a lone ``\\r``)."""
    n = text.count("\n")
    if "\r" in text:
        n += text.count("\r") - text.count("\r\n")
    return n


def _normalize_newlines(text: str) -> str:
    return text.replace("\r\n", "\n").replace("\r", "\n") if "\r" in text else text


def _not_utf8(block: bytes, e: UnicodeDecodeError, offset: int, line: int, display) -> DataFormatError:
    """The error for an invalid byte at ``e.start`` of ``block``, which starts at byte ``offset`` of the file
    and on physical line ``line``: names the byte offset in the file (a BOM counted) and that physical line."""
    line += _count_lines(block[:e.start].decode("utf-8"))   # all bytes before e.start are valid
    return DataFormatError(f"not valid UTF-8 text (byte offset {offset + e.start})", file=display, line=line)


def decode_text(raw: bytes, display) -> str:
    """The text of a whole file (UTF-8, a leading BOM skipped)."""
    bom = len(codecs.BOM_UTF8) if raw.startswith(codecs.BOM_UTF8) else 0
    try:
        return raw[bom:].decode("utf-8")
    except UnicodeDecodeError as e:
        raise _not_utf8(raw[bom:], e, bom, 1, display) from None


def _binary_blocks(fh, display, chunk_size: int, line_of_block):
    """Decoded blocks of whole lines (line breaks turned into ``\\n``) of a binary stream.

    A block is cut only after a line break (never between ``\\r`` and ``\\n``), so that a
    multi-byte UTF-8 character is never split and each block decodes on its own; an invalid
    byte raises DataFormatError with its byte offset in the file and its physical line
    (``line_of_block()``: the physical line the block starts on)."""
    carry = b""
    offset, first = 0, True
    while True:
        data = fh.read(chunk_size)
        buf = carry + data if carry else data
        if data:
            cut = max(buf.rfind(b"\n"), buf.rfind(b"\r", 0, len(buf) - 1)) + 1
            if cut == 0:             # no line break yet: read on
                carry = buf
                continue
            block, carry = buf[:cut], buf[cut:]
        else:
            block, carry = buf, b""
        if first:
            first = False
            if block.startswith(codecs.BOM_UTF8):
                block = block[len(codecs.BOM_UTF8):]
                offset = len(codecs.BOM_UTF8)
        try:
            text = block.decode("utf-8")
        except UnicodeDecodeError as e:
            raise _not_utf8(block, e, offset, line_of_block(), display) from None
        offset += len(block)
        yield _normalize_newlines(text)
        if not data:
            return


def _text_blocks(text: str, chunk_size: int):
    """Blocks of whole lines (line breaks turned into ``\\n``) of a text in memory."""
    text = _normalize_newlines(text)
    pos = 0
    while pos < len(text):
        cut = text.find("\n", pos + chunk_size - 1)
        end = len(text) if cut < 0 else cut + 1
        yield text[pos:end]
        pos = end


def _cell_problem(c: str) -> str | None:
    """Why a (stripped) cell of a required column is not a finite number (None when it is one)."""
    if _NONFINITE.fullmatch(c):
        return f"{c!r} is not allowed: values must be finite numbers"
    if not _NUMBER.fullmatch(c):
        hint = DECIMAL_COMMA_HINT if _DECIMAL_COMMA.fullmatch(c) else ""
        return f"non-numeric value {c!r}{hint}" if c else "empty cell"
    if not math.isfinite(float(c)):
        return f"value {c!r} overflows (not a finite double)"
    return None


class _Reader:
    """Checks and converts one test's CSV fed in blocks of whole lines (``\\n``-terminated but
    possibly the last); :meth:`finish` raises the problem the whole file would get or returns
    the columns.

    Problems are recorded as they are met and raised at the end in the order of precedence
    of a check of the whole file: header, too few rows, the first line with a wrong number
    of cells, the first bad cell of each required column (in the order of the format's
    columns), then time order or gaps. (An invalid UTF-8 byte, found while decoding, comes
    before all of them.)"""

    def __init__(self, test: str, display):
        self.test, self.display = test, display
        self.expected = COLUMNS[test]
        self.sweep = test in SWEEP_TESTS
        self.need = _MIN_ROWS_SWEEP if self.sweep else _MIN_ROWS_TIME_SERIES
        self.line = 1                   # physical line of the next block's first line
        self.nonblank = False           # any non-whitespace text so far (only tracked before the header)
        self.header = self.hline = None
        self.header_error: DataFormatError | None = None
        self.count_error: DataFormatError | None = None
        self.value_errors: dict[str, DataFormatError] = {}
        self.nrows = 0
        self.pieces: dict[str, list[np.ndarray]] = {e: [] for e in self.expected}
        self.runs: list[tuple[int, int | None, np.ndarray | None]] = []   # (first row, its line | lines of rows)
        self.run_rows: list[int] = []

    # ------------------------------------------------------------------ feeding
    def feed(self, text: str) -> None:
        first = self.line
        self.line += text.count("\n")
        if self.header_error is not None or self._counting_done():
            return
        pos = 0
        if self.header is None:
            pos, first = self._find_header(text, first)
            if self.header is None or self.header_error is not None or pos >= len(text):
                return
        data = text[pos:] if pos else text
        if not self._fast(data, first):
            self._slow(data, first)

    def _counting_done(self) -> bool:
        """Nothing later in the file can change the outcome (apart from an invalid byte)."""
        return self.count_error is not None and self.nrows >= self.need

    def _find_header(self, text: str, first: int) -> tuple[int, int]:
        pos, lineno = 0, first
        while pos < len(text):
            end = text.find("\n", pos)
            end = len(text) if end < 0 else end
            line = text[pos:end]
            pos = end + 1
            s = line.strip()
            if s:
                self.nonblank = True
            if s and not s.startswith("#"):
                self._set_header(line, lineno)
                return pos, lineno + 1
            lineno += 1
        return pos, lineno

    def _set_header(self, line: str, lineno: int) -> None:
        expected, display = self.expected, self.display
        header, self.hline = _split_row(line), lineno
        self.header = header
        try:
            if all(_NUMBER.fullmatch(c) or _NONFINITE.fullmatch(c) for c in header):
                raise DataFormatError(f"no header row: this line looks like data; the first non-comment line "
                                      f"must be the header {','.join(expected)}", file=display, line=lineno)
            # trailing columns without a name (as Excel writes them: "a,b,c,,") are ignored when empty
            ncol = len(header)
            while ncol > 1 and not header[ncol - 1]:
                ncol -= 1
            self.total, self.ncol, self.extra = len(header), ncol, len(header) - ncol
            named = header[:ncol]
            for j, h in enumerate(named):
                if not h:
                    raise DataFormatError("empty column name in the header", file=display, line=lineno,
                                          column=j + 1)
                if named.index(h) != j:
                    raise DataFormatError(f"duplicate column {h!r} (also column {named.index(h) + 1})",
                                          file=display, line=lineno, column=j + 1, column_name=h)
            for e in expected:
                if e not in named:
                    raise _column_problem(e, named, expected, display, lineno)
        except DataFormatError as ex:
            self.header_error = ex
            return
        self.idx = {e: named.index(e) for e in expected}
        self.usecols = tuple(self.idx[e] for e in expected)

    @property
    def _keep(self) -> bool:
        """Are the values still needed (no problem recorded yet)?"""
        return self.count_error is None and not self.value_errors

    def _store(self, row0: int, cols: list[np.ndarray], first_line: int | None, lines: np.ndarray | None) -> None:
        """Keep the values of rows ``row0``... (their lines: consecutive from ``first_line``, or ``lines``)."""
        if not len(cols[0]):
            return
        for e, c in zip(self.expected, cols):
            self.pieces[e].append(c)
        self.run_rows.append(row0)
        self.runs.append((row0, first_line, lines))

    # ------------------------------------------------------------------ fast path: a block of plain numeric lines
    def _fast(self, text: str, first: int) -> bool:
        if self.count_error is not None or not text.isascii() or '"' in text or "\0" in text:
            return False
        if text.startswith("\n") or "\n\n" in text:   # blank lines: loadtxt would skip them
            return False
        lines = text.split("\n")
        if lines[-1] == "":
            lines.pop()
        n = len(lines)
        if not n:
            return True
        if self.total == len(self.usecols):
            # every column is required: loadtxt itself checks that each line has the header's number of cells
            try:
                vals = np.loadtxt(lines, delimiter=",", comments=None, quotechar=None, dtype=np.float64, ndmin=2)
            except ValueError:
                return False
            if vals.shape != (n, self.total):     # blank lines skipped, or every line with too many cells
                return False
            return self._take(vals[:, self.usecols], n, first)
        b = np.frombuffer(text.encode("ascii"), dtype=np.uint8)
        breaks = np.flatnonzero(b == 10)
        if breaks.size < n:
            breaks = np.append(breaks, b.size)
        commas = np.flatnonzero(b == 44)
        starts = np.empty(n, dtype=np.intp)
        starts[0] = 0
        starts[1:] = breaks[:-1] + 1
        first_comma = np.searchsorted(commas, starts)
        counts = np.searchsorted(commas, breaks) - first_comma
        lo = self.ncol - 1
        if not self.extra:
            if not np.all(counts == lo):
                return False
        else:                       # up to `extra` more cells, which must be empty (spaces or tabs)
            if not np.all((counts >= lo) & (counts <= lo + self.extra)):
                return False
            tail = np.flatnonzero(counts > lo)
            if tail.size:
                mark = np.zeros(b.size + 1, dtype=np.int8)
                mark[commas[first_comma[tail] + lo]] = 1
                mark[breaks[tail]] = -1
                inside = np.cumsum(mark[:-1], dtype=np.int8).astype(bool)
                if not np.all(_TAIL_BYTES[b[inside]]):
                    return False
        del b, breaks, commas, starts, first_comma, counts
        try:
            vals = np.loadtxt(lines, delimiter=",", comments=None, quotechar=None, usecols=self.usecols,
                              dtype=np.float64, ndmin=2)
        except ValueError:
            return False
        del lines
        return self._take(vals, n, first)

    def _take(self, vals: np.ndarray, n: int, first: int) -> bool:
        """Keep the values of a block of ``n`` lines from line ``first`` if they are all there and finite."""
        if vals.shape != (n, len(self.usecols)) or not np.all(np.isfinite(vals)):
            return False
        if self._keep:
            self._store(self.nrows, [np.ascontiguousarray(vals[:, k]) for k in range(vals.shape[1])], first, None)
        self.nrows += n
        return True

    # ------------------------------------------------------------------ slow path: line by line, every check
    def _slow(self, text: str, first: int) -> None:
        ncol, extra, display, expected = self.ncol, self.extra, self.display, self.expected
        keep = self._keep
        vals: list[list[float]] = [[] for _ in expected]
        rowlines: list[int] = []
        lines = text.split("\n")
        if lines and lines[-1] == "":
            lines.pop()
        for lineno, line in enumerate(lines, start=first):
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            self.nrows += 1
            if self._counting_done():
                break
            if self.count_error is not None:
                continue
            cells = _split_row(line) if '"' in line else [c.strip() for c in line.split(",")]
            if ncol < len(cells) <= ncol + extra and not any(cells[ncol:]):
                cells = cells[:ncol]             # empty cells under the nameless trailing columns
            elif len(cells) != ncol:
                j = next((i for i in range(ncol, len(cells)) if cells[i]), None)
                if extra and j is not None and j < ncol + extra:
                    self.count_error = DataFormatError(
                        f"value {cells[j]!r} in column {j + 1}, which has no name in the header",
                        file=display, line=lineno, column=j + 1)
                else:
                    self.count_error = DataFormatError(
                        f"wrong number of cells: {len(cells)}, the header has {ncol}"
                        f"{_cell_count_hint(cells, ncol)}", file=display, line=lineno)
                keep = False
                continue
            for k, e in enumerate(expected):
                c = cells[self.idx[e]]
                if _NUMBER.fullmatch(c):
                    v = float(c)
                    if math.isfinite(v):
                        if keep:
                            vals[k].append(v)
                        continue
                if e not in self.value_errors:
                    self.value_errors[e] = DataFormatError(_cell_problem(c), file=display, line=lineno,
                                                           column=self.idx[e] + 1, column_name=e)
                keep = False
            if keep:
                rowlines.append(lineno)
        if keep and rowlines:           # (every row of this block was kept)
            self._store(self.nrows - len(rowlines), [np.array(v, dtype=np.float64) for v in vals], None,
                        np.array(rowlines, dtype=np.int64))

    # ------------------------------------------------------------------ result
    def _line_of(self, row: int) -> int:
        i = bisect.bisect_right(self.run_rows, row) - 1
        r0, l0, lines = self.runs[i]
        return l0 + (row - r0) if lines is None else int(lines[row - r0])

    def finish(self) -> dict[str, np.ndarray]:
        expected, display = self.expected, self.display
        if self.header is None:
            if not self.nonblank:
                raise DataFormatError("empty file", file=display)
            raise DataFormatError(f"no header row (the file has only comments and blank lines); expected "
                                  f"{','.join(expected)}", file=display)
        if self.header_error is not None:
            raise self.header_error
        if self.nrows < self.need:
            kind = "sweep" if self.sweep else "time series"
            raise DataFormatError(f"too few data rows: {self.nrows} (a {kind} needs at least {self.need})",
                                  file=display)
        if self.count_error is not None:
            raise self.count_error
        for e in expected:
            if e in self.value_errors:
                raise self.value_errors[e]
        out = {}
        for e in expected:              # one column at a time: peak = the arrays + one column
            parts = self.pieces.pop(e)
            out[e] = parts[0] if len(parts) == 1 else np.concatenate(parts)
            del parts
        if self.sweep:
            self._check_gaps(out["gap_mm"])
        else:
            t = out["time_s"]
            bad = np.flatnonzero(t[1:] <= t[:-1])
            if bad.size:
                k = int(bad[0]) + 1
                raise DataFormatError(f"time not strictly increasing: {float(t[k])!r} s after "
                                      f"{float(t[k - 1])!r} s on line {self._line_of(k - 1)}", file=display,
                                      line=self._line_of(k), column=self.idx["time_s"] + 1, column_name="time_s")
        return out

    def _check_gaps(self, g: np.ndarray) -> None:
        """The first row whose gap is negative or equal to an earlier row's (as a row-by-row check finds it)."""
        n = len(g)
        neg = np.flatnonzero(g < 0)
        k_neg = int(neg[0]) if neg.size else n
        order = np.argsort(g, kind="stable")
        same = np.flatnonzero(g[order][1:] == g[order][:-1]) + 1
        k_dup = int(order[same].min()) if same.size else n
        kw = dict(file=self.display, column=self.idx["gap_mm"] + 1, column_name="gap_mm")
        if k_neg < n and k_neg <= k_dup:
            raise DataFormatError(f"negative gap {g[k_neg]:g} mm", line=self._line_of(k_neg), **kw)
        if k_dup < n:
            v = g[k_dup]
            k0 = int(np.flatnonzero(g == v)[0])
            raise DataFormatError(f"duplicate gap {v:g} mm on lines {self._line_of(k0)} and {self._line_of(k_dup)} "
                                  f"(one row per gap)", line=self._line_of(k_dup), **kw)


def parse_csv(text: str, test: str, display, *, chunk_size: int = CHUNK_SIZE) -> dict[str, np.ndarray]:
    """Parse and check the text of one CSV of ``test``; returns {required column: float64 array}."""
    reader = _Reader(test, display)
    for block in _text_blocks(text, chunk_size):
        reader.feed(block)
    return reader.finish()


def read_csv(source, test: str, display=None, *, chunk_size: int = CHUNK_SIZE) -> dict[str, np.ndarray]:
    """Read and check one CSV of ``test`` from a path or a binary stream, in blocks of about ``chunk_size``
    bytes (the whole file is never held); returns {required column: float64 array}. ``display``: the name
    given in error messages (default: the path)."""
    if isinstance(source, (str, os.PathLike)):
        with open(source, "rb") as fh:
            return read_csv(fh, test, source if display is None else display, chunk_size=chunk_size)
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    reader = _Reader(test, display)
    for block in _binary_blocks(source, display, chunk_size, lambda: reader.line):
        reader.feed(block)
    return reader.finish()

def build_test(test: str, cols: dict, entry: dict, file) -> "TimeSeries | GapSweep":
    if test in SWEEP_TESTS:
        return GapSweep(test=test, file=file, gap_mm=cols["gap_mm"], current_A=cols["current_A"],
                        displacement_mm=cols.get("displacement_mm"), force_N=cols.get("force_N"),
                        field_T=entry["field_T"])
    return TimeSeries(test=test, file=file, time_s=cols["time_s"], voltage_V=cols["voltage_V"],
                      current_A=cols["current_A"], displacement_mm=cols.get("displacement_mm"),
                      force_N=cols.get("force_N"), field_T=entry["field_T"], gap_mm=entry["gap_mm"],
                      frequency_hz=entry.get("frequency_hz"))


