"""The measured-data format ``mpc-actuator-data/1``: reader, writer, validation.

A dataset is a folder holding ``manifest.json`` and one CSV file per sample and
test (see the README section "Data format" for the full description).

* :func:`read_dataset` reads and checks everything; any problem raises
  :class:`DataFormatError` (a ``ValueError``) whose message names the file and,
  where it applies, the 1-based physical line, the column, or the JSON path.
  Problems in different files are collected and reported together.
* :func:`write_dataset` writes a :class:`Dataset` (validated first) so that
  ``read_dataset(write_dataset(ds, out))`` equals ``ds``.
* :func:`dataset_summary` gives a few human-readable lines.

The reader opens files read-only and never modifies anything.
"""
from __future__ import annotations

import csv
import difflib
import json
import math
import os
import re
import tempfile
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Iterable

import numpy as np

__all__ = [
    "FORMAT", "TESTS", "TIME_SERIES_TESTS", "SWEEP_TESTS", "COLUMNS", "TEST_DESCRIPTIONS",
    "REQUIRED_TEST_KEYS", "DataFormatError", "UnknownSampleError",
    "TimeSeries", "GapSweep", "Sample", "Dataset",
    "read_dataset", "write_dataset", "dataset_summary",
]

FORMAT = "mpc-actuator-data/1"
MANIFEST = "manifest.json"

TIME_SERIES_TESTS: tuple[str, ...] = ("T2", "T3", "T4", "T5", "T6", "T8")
SWEEP_TESTS: tuple[str, ...] = ("T1", "T7")
TESTS: tuple[str, ...] = ("T1", "T2", "T3", "T4", "T5", "T6", "T7", "T8")

COLUMNS: dict[str, tuple[str, ...]] = {
    "T1": ("gap_mm", "current_A", "displacement_mm"),
    "T2": ("time_s", "voltage_V", "current_A", "displacement_mm"),
    "T3": ("time_s", "voltage_V", "current_A", "displacement_mm"),
    "T4": ("time_s", "voltage_V", "current_A", "displacement_mm"),
    "T5": ("time_s", "voltage_V", "current_A", "displacement_mm"),
    "T6": ("time_s", "voltage_V", "current_A", "displacement_mm"),
    "T7": ("gap_mm", "current_A", "force_N"),
    "T8": ("time_s", "voltage_V", "current_A", "force_N"),
}

# Paper, Table 2.
TEST_DESCRIPTIONS: dict[str, str] = {
    "T1": "Steady-state displacement vs gap at 0.23 T (gap sweep)",
    "T2": "Displacement step response at 0.06 T, gap = gap of maximum T1 displacement + 2 mm",
    "T3": "Displacement step response at 0.11 T, gap = gap of maximum T1 displacement + 2 mm",
    "T4": "Displacement step response at 0.16 T, gap = gap of maximum T1 displacement + 2 mm",
    "T5": "Displacement step response at 0.23 T, gap = gap of maximum T1 displacement + 2 mm",
    "T6": "Displacement under 1 Hz sinusoidal excitation at 0.23 T, gap = gap of maximum T1 displacement + 3 mm",
    "T7": "Steady-state blocked force vs gap (gap sweep)",
    "T8": "Blocked force step response at 0.23 T, gap 2 mm",
}

# Keys of a test entry in the manifest: required ones (besides "file").
REQUIRED_TEST_KEYS: dict[str, tuple[str, ...]] = {
    t: ("field_T",) if t in SWEEP_TESTS else ("field_T", "gap_mm", "frequency_hz") if t == "T6"
    else ("field_T", "gap_mm")
    for t in TESTS
}

_TOP_KEYS = ("format", "synthetic", "description", "rig", "samples")
_SAMPLE_KEYS = ("id", "wt_pct", "diameter_mm", "thickness_mm", "tests")
_MIN_ROWS_TIME_SERIES = 2
_MIN_ROWS_SWEEP = 1
_MAX_REPORTED = 50

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_NONFINITE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)
_LINE_SPLIT = re.compile(r"\r\n|\n|\r")


# ====================================================================== errors
class DataFormatError(ValueError):
    """A dataset does not follow ``mpc-actuator-data/1``.

    Attributes: ``file`` (path of the offending file or None), ``line`` (1-based
    physical line), ``column`` (1-based CSV column number), ``column_name``,
    ``key`` (JSON path in the manifest, e.g. ``samples[2].tests.T3.gap_mm``) and
    ``problems`` (all individual errors when several were collected; else ``[self]``).
    """

    def __init__(self, message: str, *, file=None, line: int | None = None, column: int | None = None,
                 column_name: str | None = None, key: str | None = None,
                 problems: list["DataFormatError"] | None = None):
        self.file = None if file is None else Path(file)
        self.line, self.column, self.column_name, self.key = line, column, column_name, key
        self.reason = message
        where = []
        if file is not None:
            where.append(str(file))
        if line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column {column}" + (f" ({column_name!r})" if column_name else ""))
        elif column_name:
            where.append(f"column {column_name!r}")
        loc = ", ".join(where)
        if key:
            loc = f"{loc}: {key}" if loc else key
        self.message = f"{loc}: {message}" if loc else message
        self.problems = problems if problems is not None else [self]
        super().__init__(self.message)

    def __str__(self) -> str:  # (KeyError would repr() the message)
        return self.message


class UnknownSampleError(DataFormatError, KeyError):
    """A sample id that is not in the dataset (also a ``KeyError``)."""


def _combine(problems: list[DataFormatError], what: str) -> DataFormatError:
    if len(problems) == 1:
        return problems[0]
    shown = problems[:_MAX_REPORTED]
    lines = [f"{len(problems)} problems in {what}:"] + [f"  - {p.message}" for p in shown]
    if len(problems) > len(shown):
        lines.append(f"  ... and {len(problems) - len(shown)} more")
    return DataFormatError("\n".join(lines), problems=list(problems))


# ====================================================================== data classes
def _arr(x):
    if x is None:
        return None
    a = np.asarray(x, dtype=float)
    if a.ndim != 1:
        raise ValueError(f"expected a 1-D array, got shape {a.shape}")
    return a


def _values_equal(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if a is None or b is None:
            return False
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))
    return a == b


class _ArrayEq:
    """Field-wise equality that compares numpy arrays by value (fields with compare=False skipped)."""

    def __eq__(self, other):
        if type(other) is not type(self):
            return NotImplemented
        return all(_values_equal(getattr(self, f.name), getattr(other, f.name))
                   for f in fields(self) if f.compare)

    __hash__ = None


@dataclass(eq=False)
class TimeSeries(_ArrayEq):
    """A time-series test (T2-T6: displacement; T8: blocked force)."""
    test: str
    file: Path | None = field(compare=False)
    time_s: np.ndarray
    voltage_V: np.ndarray
    current_A: np.ndarray
    displacement_mm: np.ndarray | None
    force_N: np.ndarray | None
    field_T: float
    gap_mm: float
    frequency_hz: float | None = None

    def __post_init__(self):
        self.file = None if self.file is None else Path(self.file)
        for name in ("time_s", "voltage_V", "current_A", "displacement_mm", "force_N"):
            setattr(self, name, _arr(getattr(self, name)))


@dataclass(eq=False)
class GapSweep(_ArrayEq):
    """A gap sweep of steady-state values, one row per gap (T1: displacement; T7: blocked force)."""
    test: str
    file: Path | None = field(compare=False)
    gap_mm: np.ndarray
    current_A: np.ndarray
    displacement_mm: np.ndarray | None
    force_N: np.ndarray | None
    field_T: float

    def __post_init__(self):
        self.file = None if self.file is None else Path(self.file)
        for name in ("gap_mm", "current_A", "displacement_mm", "force_N"):
            setattr(self, name, _arr(getattr(self, name)))


@dataclass
class Sample:
    id: str
    wt_pct: float
    diameter_mm: float
    thickness_mm: float
    tests: dict = field(default_factory=dict)   # dict[str, TimeSeries | GapSweep], in T1..T8 order

    def test(self, name: str) -> "TimeSeries | GapSweep":
        """The test ``name``; DataFormatError naming the tests this sample has otherwise."""
        try:
            return self.tests[name]
        except KeyError:
            raise DataFormatError(f"sample {self.id!r} has no test {name!r} "
                                  f"(it has {', '.join(self.tests) or 'no tests'})") from None


@dataclass
class Dataset:
    root: Path | None = field(compare=False)
    synthetic: bool
    description: str
    rig: dict
    samples: list

    def __post_init__(self):
        self.root = None if self.root is None else Path(self.root)

    @property
    def sample_ids(self) -> list[str]:
        return [s.id for s in self.samples]

    def sample(self, id: str) -> Sample:
        """The sample with this id; UnknownSampleError (a DataFormatError and KeyError) otherwise."""
        for s in self.samples:
            if s.id == id:
                return s
        raise UnknownSampleError(f"no sample {id!r} in dataset {self.root} "
                                 f"(known ids: {', '.join(self.sample_ids) or 'none'})")

    @property
    def field_per_amp_T_per_A(self) -> float | None:
        v = (self.rig or {}).get("field_per_amp_T_per_A")
        return None if v is None else float(v)

    @property
    def coil_radius_mm(self) -> float | None:
        v = (self.rig or {}).get("coil_radius_mm")
        return None if v is None else float(v)


# ====================================================================== manifest
def _jpath(parts) -> str:
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def _typename(v) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "boolean"
    if isinstance(v, (int, float)):
        return "number"
    if isinstance(v, str):
        return "string"
    if isinstance(v, list):
        return "array"
    if isinstance(v, dict):
        return "object"
    return type(v).__name__


def _show(v) -> str:
    s = json.dumps(v, default=str) if not isinstance(v, str) else repr(v)
    return s if len(s) <= 40 else s[:37] + "..."


class _Manifest:
    """Checks a parsed manifest, collecting problems; keeps the checked values."""

    def __init__(self, obj, mfile):
        self.mfile = mfile
        self.problems: list[DataFormatError] = []
        self.samples: list[dict] = []
        self.synthetic = False
        self.description = ""
        self.rig: dict = {}
        self._check(obj)

    def err(self, parts, msg):
        self.problems.append(DataFormatError(msg, file=self.mfile, key=_jpath(parts) or None))

    def unknown_keys(self, obj: dict, allowed, parts):
        for k in obj:
            if k not in allowed:
                close = difflib.get_close_matches(k, allowed, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else f" (allowed keys: {', '.join(allowed)})"
                self.err(parts + [k], f"unknown key {k!r}{hint}")

    def require(self, obj: dict, key, parts) -> bool:
        if key not in obj:
            self.err(parts + [key], f"missing required key {key!r}")
            return False
        return True

    def number(self, obj, key, parts, *, lo=None, lo_open=False, hi=None, optional=False):
        """Checked float value of obj[key] (None when absent/invalid; absent allowed if optional)."""
        if key not in obj or (optional and obj[key] is None):
            if not optional:
                self.require(obj, key, parts)
            return None
        v = obj[key]
        p = parts + [key]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.err(p, f"{key} must be a number, got {_typename(v)} {_show(v)}")
            return None
        v = float(v)
        if not math.isfinite(v):
            self.err(p, f"{key} must be finite, got {v}")
            return None
        if lo is not None and (v <= lo if lo_open else v < lo):
            self.err(p, f"{key} must be {'>' if lo_open else '>='} {lo:g}, got {v:g}")
            return None
        if hi is not None and v > hi:
            self.err(p, f"{key} must be <= {hi:g}, got {v:g}")
            return None
        return v

    def _check(self, obj):
        if not isinstance(obj, dict):
            self.err([], f"the manifest must be a JSON object, got {_typename(obj)}")
            return
        if "format" not in obj:
            self.err(["format"], f"missing required key 'format' (expected \"format\": \"{FORMAT}\")")
            return
        if obj["format"] != FORMAT:
            self.err(["format"], f"unsupported format {_show(obj['format'])}; this reader reads {FORMAT!r}")
            return
        self.unknown_keys(obj, _TOP_KEYS, [])
        if self.require(obj, "synthetic", []):
            if not isinstance(obj["synthetic"], bool):
                self.err(["synthetic"], f"synthetic must be true or false, got {_typename(obj['synthetic'])} "
                                        f"{_show(obj['synthetic'])}")
            else:
                self.synthetic = obj["synthetic"]
        if "description" in obj:
            if not isinstance(obj["description"], str):
                self.err(["description"], f"description must be a string, got {_typename(obj['description'])}")
            else:
                self.description = obj["description"]
        if "rig" in obj:
            rig = obj["rig"]
            if not isinstance(rig, dict):
                self.err(["rig"], f"rig must be an object, got {_typename(rig)}")
            else:
                self.number(rig, "coil_radius_mm", ["rig"], lo=0, lo_open=True, optional=True)
                self.number(rig, "field_per_amp_T_per_A", ["rig"], lo=0, lo_open=True, optional=True)
                self.rig = rig
        if not self.require(obj, "samples", []):
            return
        samples = obj["samples"]
        if not isinstance(samples, list):
            self.err(["samples"], f"samples must be an array, got {_typename(samples)}")
            return
        seen: dict[str, int] = {}
        for i, s in enumerate(samples):
            self._check_sample(s, i, seen)

    def _check_sample(self, s, i, seen):
        parts = ["samples", i]
        if not isinstance(s, dict):
            self.err(parts, f"a sample must be an object, got {_typename(s)}")
            return
        self.unknown_keys(s, _SAMPLE_KEYS, parts)
        ok = True
        sid = s.get("id")
        if not self.require(s, "id", parts):
            ok = False
        elif not isinstance(sid, str) or not sid.strip():
            self.err(parts + ["id"], f"id must be a non-empty string, got {_typename(sid)} {_show(sid)}")
            ok = False
        elif sid in seen:
            self.err(parts + ["id"], f"duplicate sample id {sid!r} (also samples[{seen[sid]}].id)")
            ok = False
        else:
            seen[sid] = i
        wt = self.number(s, "wt_pct", parts, lo=0, hi=100)
        dia = self.number(s, "diameter_mm", parts, lo=0, lo_open=True)
        th = self.number(s, "thickness_mm", parts, lo=0, lo_open=True)
        ok = ok and None not in (wt, dia, th)
        tests = {}
        if not self.require(s, "tests", parts):
            ok = False
        elif not isinstance(s["tests"], dict):
            self.err(parts + ["tests"], f"tests must be an object mapping test names to entries, "
                                        f"got {_typename(s['tests'])}")
            ok = False
        else:
            for name, entry in s["tests"].items():
                e = self._check_test(name, entry, parts + ["tests", name])
                if e is None:
                    ok = False
                else:
                    tests[name] = e
        if ok:
            order = {t: k for k, t in enumerate(TESTS)}
            self.samples.append(dict(id=sid, wt_pct=wt, diameter_mm=dia, thickness_mm=th, index=i,
                                     tests=dict(sorted(tests.items(), key=lambda kv: order[kv[0]]))))

    def _check_test(self, name, entry, parts):
        if name not in TESTS:
            close = difflib.get_close_matches(name, TESTS, n=1) or \
                [t for t in TESTS if t.lower() == str(name).lower()]
            hint = f"; did you mean {close[0]!r}?" if close else ""
            self.err(parts, f"unknown test {name!r} (known tests: {', '.join(TESTS)}){hint}")
            return None
        if not isinstance(entry, dict):
            self.err(parts, f"a test entry must be an object, got {_typename(entry)}")
            return None
        required = REQUIRED_TEST_KEYS[name]
        self.unknown_keys(entry, ("file",) + required, parts)
        out = {"key": _jpath(parts)}
        ok = True
        if not self.require(entry, "file", parts):
            ok = False
        else:
            f = entry["file"]
            if not isinstance(f, str) or not f.strip():
                self.err(parts + ["file"], f"file must be a non-empty string (path relative to the dataset "
                                           f"folder), got {_typename(f)} {_show(f)}")
                ok = False
            elif f.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", f) or Path(f).is_absolute():
                self.err(parts + ["file"], f"file {f!r} is an absolute path; it must be relative to the "
                                           f"dataset folder")
                ok = False
            elif "\\" in f:
                self.err(parts + ["file"], f"file {f!r}: use '/' as the path separator")
                ok = False
            else:
                out["file"] = f
        limits = {"field_T": dict(lo=0, lo_open=True), "gap_mm": dict(lo=0),
                  "frequency_hz": dict(lo=0, lo_open=True)}
        for k in required:
            v = self.number(entry, k, parts, **limits[k])
            if v is None:
                ok = False
            out[k] = v
        return out if ok else None


def _load_json(mfile: Path):
    try:
        with open(mfile, "rb") as fh:
            raw = fh.read()
    except FileNotFoundError:
        raise DataFormatError("manifest not found", file=mfile) from None
    except OSError as e:
        raise DataFormatError(f"cannot read manifest: {e.strerror or e}", file=mfile) from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw[:e.start].count(b"\n") + 1
        raise DataFormatError(f"not valid UTF-8 (byte {e.start})", file=mfile, line=line) from None
    if not text.strip():
        raise DataFormatError("empty manifest", file=mfile)

    def pairs(kv):
        d = {}
        for k, v in kv:
            if k in d:
                raise DataFormatError(f"duplicate key {k!r} in a JSON object", file=mfile)
            d[k] = v
        return d

    try:
        return json.loads(text, object_pairs_hook=pairs)
    except json.JSONDecodeError as e:
        raise DataFormatError(f"invalid JSON: {e.msg}", file=mfile, line=e.lineno, column=e.colno) from None


# ====================================================================== CSV
def _decode(raw: bytes, display) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw[:e.start].count(b"\n") + 1
        raise DataFormatError(f"not valid UTF-8 text (byte offset {e.start})", file=display, line=line) from None


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


def _parse_csv(text: str, test: str, display) -> dict[str, np.ndarray]:
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
    # header
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
    ncol = len(header)
    for lineno, cells in rows:
        if len(cells) != ncol:
            hint = " (decimal commas are not allowed; use '.')" if len(cells) > ncol else ""
            raise DataFormatError(f"wrong number of cells: {len(cells)}, the header has {ncol}{hint}",
                                  file=display, line=lineno)
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
                raise DataFormatError(f"non-numeric value {c!r}" if c else "empty cell", **kw)
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


def _build_test(test: str, cols: dict, entry: dict, file) -> "TimeSeries | GapSweep":
    if test in SWEEP_TESTS:
        return GapSweep(test=test, file=file, gap_mm=cols["gap_mm"], current_A=cols["current_A"],
                        displacement_mm=cols.get("displacement_mm"), force_N=cols.get("force_N"),
                        field_T=entry["field_T"])
    return TimeSeries(test=test, file=file, time_s=cols["time_s"], voltage_V=cols["voltage_V"],
                      current_A=cols["current_A"], displacement_mm=cols.get("displacement_mm"),
                      force_N=cols.get("force_N"), field_T=entry["field_T"], gap_mm=entry["gap_mm"],
                      frequency_hz=entry.get("frequency_hz"))


# ====================================================================== reader
def _normalize_tests(tests) -> tuple[str, ...]:
    if tests is None:
        return ()
    if isinstance(tests, str):
        tests = (tests,)
    tests = tuple(tests)
    bad = [t for t in tests if t not in TESTS]
    if bad:
        raise ValueError(f"unknown test name(s) {', '.join(map(repr, bad))} (known: {', '.join(TESTS)})")
    return tests


def read_dataset(path, tests: Iterable[str] | None = None, samples: Iterable[str] | None = None) -> Dataset:
    """Read and check a dataset folder (or the path of its manifest.json).

    ``tests``: test names every selected sample must have (validate mode);
    ``samples``: ids of the samples to load (manifest order is kept; unknown ids are an error).
    Raises DataFormatError naming file, line, column or JSON key of every problem found.
    """
    need = _normalize_tests(tests)
    path = Path(path)
    if path.is_file() or path.name == MANIFEST and not path.is_dir():
        root, mfile = path.parent, path
    else:
        root, mfile = path, path / MANIFEST
    if not root.is_dir():
        raise DataFormatError("dataset folder not found", file=root)
    if not mfile.is_file():
        raise DataFormatError(f"manifest not found (a dataset folder must contain {MANIFEST})", file=mfile)
    m = _Manifest(_load_json(mfile), mfile)
    problems = list(m.problems)
    entries = m.samples
    if samples is not None:
        if isinstance(samples, str):
            samples = [samples]
        wanted = list(samples)
        all_ids = [e["id"] for e in entries]
        unknown = [s for s in wanted if s not in all_ids]
        if unknown:
            problems.append(UnknownSampleError(
                f"unknown sample id(s) {', '.join(map(repr, unknown))} (known ids: {', '.join(all_ids) or 'none'})",
                file=mfile))
        entries = [e for e in entries if e["id"] in set(wanted)]
    for e in entries:
        missing = [t for t in need if t not in e["tests"]]
        if missing:
            problems.append(DataFormatError(
                f"sample {e['id']!r} lacks test(s) {', '.join(missing)} needed here "
                f"(it has {', '.join(e['tests']) or 'none'})", file=mfile, key=f"samples[{e['index']}].tests"))
    root_resolved = root.resolve()
    out_samples = []
    for e in entries:
        tests_out = {}
        for name, te in e["tests"].items():
            display = root / te["file"]
            try:
                target = display.resolve()
                if not target.is_relative_to(root_resolved):
                    raise DataFormatError(f"file {te['file']!r} is outside the dataset folder {root}",
                                          file=mfile, key=te["key"] + ".file")
                if not target.exists():
                    raise DataFormatError(f"file {te['file']!r} does not exist ({display})",
                                          file=mfile, key=te["key"] + ".file")
                if not target.is_file():
                    raise DataFormatError(f"file {te['file']!r} is not a regular file ({display})",
                                          file=mfile, key=te["key"] + ".file")
                try:
                    with open(target, "rb") as fh:
                        raw = fh.read()
                except OSError as ex:
                    raise DataFormatError(f"cannot read: {ex.strerror or ex}", file=display) from None
                cols = _parse_csv(_decode(raw, display), name, display)
                tests_out[name] = _build_test(name, cols, te, display)
            except DataFormatError as ex:
                problems.append(ex)
        out_samples.append(Sample(id=e["id"], wt_pct=e["wt_pct"], diameter_mm=e["diameter_mm"],
                                  thickness_mm=e["thickness_mm"], tests=tests_out))
    if problems:
        raise _combine(problems, f"dataset {root}")
    ds = Dataset(root=root, synthetic=m.synthetic, description=m.description, rig=m.rig, samples=out_samples)
    ds._read_from = root_resolved   # provenance: write_dataset never writes over this folder
    return ds


# ====================================================================== writer
def _fmt(x: float) -> str:
    return repr(float(x))   # shortest string that round-trips exactly


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"{type(o).__name__} is not JSON serializable")


def _num_json(x):
    x = float(x)
    return int(x) if x.is_integer() and abs(x) < 2**53 else x


def _safe_dirname(sid: str, used: set) -> str:
    base = re.sub(r"[^A-Za-z0-9._-]+", "_", sid).strip("._") or "sample"
    name, k = base, 2
    while name.lower() in used:
        name, k = f"{base}_{k}", k + 1
    used.add(name.lower())
    return name


def _csv_text(ds: Dataset, s: Sample, name: str, t) -> str:
    cols = COLUMNS[name]
    arrays = [getattr(t, c) for c in cols]
    lines = []
    if ds.synthetic:
        lines.append(f"# synthetic data (not measured): sample {s.id}, test {name}, {FORMAT}")
    else:
        lines.append(f"# sample {s.id}, test {name}, {FORMAT}")
    lines.append(",".join(cols))
    for row in zip(*arrays):
        lines.append(",".join(_fmt(v) for v in row))
    return "\n".join(lines) + "\n"


def _check_test_object(s: Sample, name: str, t) -> str | None:
    """Why this in-memory test cannot be written (None when fine)."""
    want = GapSweep if name in SWEEP_TESTS else TimeSeries
    if name not in TESTS:
        return f"unknown test name {name!r} (known: {', '.join(TESTS)})"
    if not isinstance(t, want):
        return f"{name} must be a {want.__name__}, got {type(t).__name__}"
    if t.test != name:
        return f"stored under {name!r} but its .test is {t.test!r}"
    cols = COLUMNS[name]
    for c in ("displacement_mm", "force_N"):
        if c not in cols and getattr(t, c) is not None:
            return f"{name} has no {c} column in this format but .{c} is set"
    missing = [c for c in cols if getattr(t, c) is None]
    if missing:
        return f"{name} needs {', '.join(missing)}"
    lens = {c: len(getattr(t, c)) for c in cols}
    if len(set(lens.values())) != 1:
        return "arrays differ in length: " + ", ".join(f"{c} {n}" for c, n in lens.items())
    if isinstance(t, TimeSeries) and name != "T6" and t.frequency_hz is not None:
        return f"frequency_hz is only defined for T6, but {name} has {t.frequency_hz!r}"
    return None


def _existing_manifest_is_measured(out: Path) -> bool:
    mf = out / MANIFEST
    if not mf.exists():
        return False
    try:
        obj = json.loads(mf.read_text(encoding="utf-8-sig"))
        return not (isinstance(obj, dict) and obj.get("synthetic") is True)
    except (OSError, ValueError):
        return True


def write_dataset(ds: Dataset, out_dir, overwrite: bool = False) -> Path:
    """Write ``ds`` as an ``mpc-actuator-data/1`` folder ``out_dir``; returns the folder path.

    Files: ``manifest.json`` (written last) and ``<sample>/<test>.csv``. Everything is
    validated before anything is written. Refuses a non-empty existing folder unless
    ``overwrite`` (FileExistsError); even then never writes into, above or below the
    folder a dataset was read from, nor over a folder holding measured (non-synthetic) data.
    """
    out = Path(out_dir)
    out_r = out.resolve()
    protected = [p for p in (getattr(ds, "_read_from", None),) if p is not None]
    for p in protected:
        if out_r == p or out_r.is_relative_to(p) or p.is_relative_to(out_r):
            raise DataFormatError(f"refusing to write into {out}: it contains (or is inside) the dataset "
                                  f"folder {p} this dataset was read from", file=out)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise FileExistsError(f"refusing to write dataset into non-empty folder {out} "
                                  f"(pass overwrite=True to replace its files)")
        if _existing_manifest_is_measured(out):
            raise FileExistsError(f"refusing to overwrite {out}: its {MANIFEST} is not a synthetic dataset "
                                  f"(measured data are never overwritten)")
    # build and validate everything in memory
    problems: list[DataFormatError] = []
    mfile = out / MANIFEST
    used: set = set()
    files: dict[str, str] = {}
    msamples = []
    for s in ds.samples:
        d = _safe_dirname(str(s.id), used)
        tests = {}
        for name, t in (s.tests or {}).items():
            why = _check_test_object(s, name, t)
            if why:
                problems.append(DataFormatError(f"cannot write sample {s.id!r} test {name!r}: {why}"))
                continue
            rel = f"{d}/{name}.csv"
            entry = {"file": rel, "field_T": t.field_T}
            if isinstance(t, TimeSeries):
                entry["gap_mm"] = t.gap_mm
                if name == "T6":
                    entry["frequency_hz"] = t.frequency_hz
            tests[name] = entry
            text = _csv_text(ds, s, name, t)
            try:
                _parse_csv(text, name, out / rel)
            except DataFormatError as e:
                problems.append(DataFormatError(f"cannot write sample {s.id!r} test {name}: {e.message}"))
                continue
            files[rel] = text
        msamples.append({"id": s.id, "wt_pct": s.wt_pct, "diameter_mm": s.diameter_mm,
                         "thickness_mm": s.thickness_mm, "tests": tests})
    manifest = {"format": FORMAT, "synthetic": ds.synthetic, "description": ds.description or "",
                "rig": dict(ds.rig or {}), "samples": msamples}
    try:
        mtext = json.dumps(manifest, indent=2, default=_json_default, allow_nan=False, ensure_ascii=False)
        plain = json.loads(mtext)
    except (TypeError, ValueError) as e:
        raise DataFormatError(f"cannot write manifest: {e}", file=mfile) from None
    for sm in plain["samples"]:   # integral metadata as JSON integers (wt_pct 20, not 20.0)
        for k in ("wt_pct", "diameter_mm", "thickness_mm"):
            if isinstance(sm.get(k), (int, float)) and not isinstance(sm.get(k), bool):
                sm[k] = _num_json(sm[k])
    problems.extend(_Manifest(plain, mfile).problems)
    if problems:
        raise _combine(problems, f"dataset to be written to {out}")
    mtext = json.dumps(plain, indent=2, ensure_ascii=False) + "\n"
    # write: CSVs first, manifest last (a half-written folder has no manifest)
    out.mkdir(parents=True, exist_ok=True)
    for rel, text in files.items():
        _atomic_write(out / rel, text)
    _atomic_write(mfile, mtext)
    return out


def _atomic_write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
        umask = os.umask(0)  # mkstemp makes 0600; give the file the mode a plain open() would
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


# ====================================================================== summary
def dataset_summary(ds: Dataset) -> str:
    """A few human-readable lines: data kind, rig, samples and their tests."""
    kind = "SYNTHETIC data (not measured)" if ds.synthetic else "measured data"
    lines = [f"dataset {ds.root if ds.root is not None else '(in memory)'}: {FORMAT}, {kind}"]
    if ds.description:
        d = " ".join(ds.description.split())
        lines.append(f"  description: {d if len(d) <= 100 else d[:97] + '...'}")
    kb = ds.field_per_amp_T_per_A
    cr = ds.coil_radius_mm
    lines.append(f"  rig: coil radius {f'{cr:g} mm' if cr is not None else 'not given'}, "
                 f"field per amp {f'{kb:g} T/A' if kb is not None else 'not given (derive from data)'}")
    lines.append(f"  {len(ds.samples)} sample(s):")
    for s in ds.samples:
        parts = []
        for name, t in s.tests.items():
            n = len(t.gap_mm) if isinstance(t, GapSweep) else len(t.time_s)
            parts.append(f"{name}({n} {'gaps' if isinstance(t, GapSweep) else 'pts'})")
        lines.append(f"    {s.id}: {s.wt_pct:g} wt%, {s.diameter_mm:g} mm, {s.thickness_mm:g} mm thick; "
                     f"tests {' '.join(parts) or 'none'}")
    return "\n".join(lines)
