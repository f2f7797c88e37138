"""The ``mpc-actuator-data/1`` format: its name, the per-test tables and the error type.

The test tables (names, CSV columns, descriptions, manifest keys) are derived from the
test protocol (:mod:`harness.data.protocol`, paper Table 2).
"""
from __future__ import annotations

from pathlib import Path

from harness.data import protocol

__all__ = [
    "FORMAT", "MANIFEST", "TESTS", "TIME_SERIES_TESTS", "SWEEP_TESTS", "COLUMNS", "TEST_DESCRIPTIONS",
    "REQUIRED_TEST_KEYS", "DataFormatError", "UnknownSampleError", "combine_problems", "DECIMAL_COMMA_HINT",
    "SEPARATOR_HINT",
]

FORMAT = "mpc-actuator-data/1"
MANIFEST = "manifest.json"

TIME_SERIES_TESTS: tuple[str, ...] = protocol.TIME_SERIES_TESTS     # T2-T6, T8
SWEEP_TESTS: tuple[str, ...] = protocol.SWEEP_TESTS                 # T1, T7
TESTS: tuple[str, ...] = tuple(protocol.TESTS)                      # T1..T8

# CSV columns of each test, in the order the writer uses.
COLUMNS: dict[str, tuple[str, ...]] = {n: d.columns for n, d in protocol.TESTS.items()}

# Paper, Table 2.
TEST_DESCRIPTIONS: dict[str, str] = {n: d.description for n, d in protocol.TESTS.items()}

# Keys of a test entry in the manifest: required ones (besides "file").
REQUIRED_TEST_KEYS: dict[str, tuple[str, ...]] = {
    n: ("field_T",) if d.is_sweep else ("field_T", "gap_mm") + (("frequency_hz",) if d.frequency_hz is not None
                                                                 else ())
    for n, d in protocol.TESTS.items()
}

MAX_REPORTED = 50   # problems listed in a combined error message

# Hints of the CSV readers (harness.data.csvfile) when a file seems written in another CSV dialect (decimal commas,
# semicolons between cells). Such files come in sets (a spreadsheet export of every test): combine_problems reports
# all of them in one line, the first in full, and points to the lab import, which reads those dialects.
DECIMAL_COMMA_HINT = " (decimal commas are not allowed; use '.')"
SEPARATOR_HINT = "; the header seems to be separated by {}, the format uses commas"
_DIALECT_MARKS = (DECIMAL_COMMA_HINT, SEPARATOR_HINT.split("{}")[0])

# ====================================================================== errors
def location_text(file=None, line: int | None = None, column: int | None = None, column_name: str | None = None,
                  key: str | None = None) -> str:
    """Where a problem is, for an error message: ``"<file>, line <n>, column <k> ('<name>'): <key>"`` with the
    parts that are known ("" when none is)."""
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
    return loc


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
        loc = location_text(file, line, column, column_name, key)
        self.message = f"{loc}: {message}" if loc else message
        self.problems = problems if problems is not None else [self]
        super().__init__(self.message)

    def __str__(self) -> str:  # (KeyError would repr() the message)
        return self.message


class UnknownSampleError(DataFormatError, KeyError):
    """A sample id that is not in the dataset (also a ``KeyError``)."""


def _dialect(p: DataFormatError) -> str | None:
    return next((m for m in _DIALECT_MARKS if m in p.reason), None)


def _same_dialect(group: list[DataFormatError]) -> DataFormatError:
    """One problem for files that all seem written in the same other CSV dialect: the first in full, the others
    counted (with a few names), and the lab import that converts them."""
    first, files = group[0], list(dict.fromkeys(str(p.file) for p in group[1:] if p.file != group[0].file))
    more = ""
    if files:
        names = ", ".join(Path(f).name if Path(f).parent == first.file.parent else f for f in files[:3])
        more = f"; the same in {len(files)} more file{'s' if len(files) > 1 else ''} ({names}{', ...' if len(files) > 3 else ''})"
    return DataFormatError(f"{first.message}{more}; `mpc-actuator import` converts files of other CSV dialects "
                           f"(decimal commas, semicolons) into the format", problems=list(group))


def combine_problems(problems: list[DataFormatError], what: str) -> DataFormatError:
    """One error for the problems of a dataset: the only one itself, else a list (problems of files in another CSV
    dialect, e.g. decimal commas, count as one line: :func:`_same_dialect`)."""
    groups: dict = {}
    for p in problems:
        groups.setdefault(_dialect(p) or id(p), []).append(p)
    if len(groups) < len(problems):
        merged = [_same_dialect(g) if len(g) > 1 else g[0] for g in groups.values()]
        out = combine_problems(merged, what) if len(merged) > 1 else merged[0]
        out.problems = list(problems)
        return out
    if len(problems) == 1:
        return problems[0]
    shown = problems[:MAX_REPORTED]
    lines = [f"{len(problems)} problems in {what}:"] + [f"  - {p.message}" for p in shown]
    if len(problems) > len(shown):
        lines.append(f"  ... and {len(problems) - len(shown)} more")
    return DataFormatError("\n".join(lines), problems=list(problems))


