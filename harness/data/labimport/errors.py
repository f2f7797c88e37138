"""The typed error of the lab-file import."""
from __future__ import annotations

from pathlib import Path

from harness.data.format import location_text

__all__ = ["LabImportError"]


class LabImportError(ValueError):
    """A lab file or mapping cannot be imported.

    Attributes: ``file`` (path of the offending file or mapping, or None), ``line`` (1-based
    physical line), ``column`` (1-based column number), ``column_name`` (header or channel
    name), ``key`` (JSON path in the mapping, e.g. ``samples[0].tests.T5.columns.time``) and
    ``reason`` (the problem without its location). The message names all of them that apply.
    """

    def __init__(self, reason: str, *, file=None, line: int | None = None, column: int | None = None,
                 column_name: str | None = None, key: str | None = None):
        self.file = None if file is None else Path(file)
        self.line, self.column, self.column_name, self.key, self.reason = line, column, column_name, key, reason
        loc = location_text(file, line, column, column_name, key)
        self.message = f"{loc}: {reason}" if loc else reason
        super().__init__(self.message)

    def __str__(self) -> str:
        return self.message
