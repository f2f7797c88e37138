"""What every reader returns: named channels of numbers with their units and where they came from."""
from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.data.labimport.errors import LabImportError
from harness.data.labimport.units import split_unit

__all__ = ["Channel", "Table"]


@dataclass
class Channel:
    """One column or channel: ``values`` (as written in the file), ``unit`` (as written, or None),
    ``column`` (1-based column of a text file, else None), ``lines`` (1-based physical line of each
    value in a text file, else None), ``time_s`` (a time base the file itself defines, e.g. a TDMS
    waveform's or an LVM file's X0 + i*Delta_X, in s; else None)."""
    name: str
    values: np.ndarray
    unit: str | None = None
    column: int | None = None
    lines: np.ndarray | None = None
    time_s: np.ndarray | None = None

    @property
    def base_name(self) -> str:
        return split_unit(self.name)[0]


@dataclass
class Table:
    """The channels read from one file, in file order, plus the reader's notes (dialect etc.)."""
    file: Path
    channels: list
    notes: dict = field(default_factory=dict)

    def names(self) -> list[str]:
        return [c.name for c in self.channels]

    def find(self, ref, *, key: str | None = None) -> Channel:
        """The channel named ``ref`` (exact, then without its unit, then case-insensitively) or,
        for an int, the 1-based column ``ref``. LabImportError listing the channels otherwise."""
        if isinstance(ref, bool) or not isinstance(ref, (int, str)):
            raise LabImportError(f"a column is named by a string or a 1-based column number, got {ref!r}",
                                 file=self.file, key=key)
        if isinstance(ref, int):
            if 1 <= ref <= len(self.channels):
                return self.channels[ref - 1]
            raise LabImportError(f"column number {ref} does not exist (the file has {len(self.channels)} columns)",
                                 file=self.file, key=key)
        for test in (lambda c: c.name == ref, lambda c: c.base_name == ref,
                     lambda c: "/" in c.name and c.name.rsplit("/", 1)[1] == ref,      # TDMS channel alone
                     lambda c: c.name.casefold() == ref.casefold(),
                     lambda c: c.base_name.casefold() == split_unit(ref)[0].casefold()):
            hits = [c for c in self.channels if test(c)]
            if len(hits) == 1:
                return hits[0]
            if len(hits) > 1:
                raise LabImportError(f"{ref!r} matches several columns ({', '.join(c.name for c in hits)}); "
                                     f"name it exactly", file=self.file, key=key)
        names = self.names()
        close = difflib.get_close_matches(ref, names, n=1, cutoff=0.6)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise LabImportError(f"no column or channel {ref!r} in this file{hint}; it has: "
                             f"{', '.join(repr(n) for n in names) or 'none'}", file=self.file, key=key)
