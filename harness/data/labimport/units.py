"""Units of lab columns: parsing them out of header names and converting to the format's units.

The format ``mpc-actuator-data/1`` stores time in s, voltage in V, current in A, displacement
and gap in mm and force in N. A header carries its unit in brackets or parentheses
(``Time [s]``, ``Current (mA)``, ``Displacement [µm]``) or as the format's suffix
(``current_mA``). Micro may be written ``µ`` (U+00B5), ``μ`` (U+03BC) or ``u``.
"""
from __future__ import annotations

import re

import numpy as np

from harness.data.labimport.errors import LabImportError

__all__ = ["ROLES", "ROLE_COLUMN", "ROLE_QUANTITY", "QUANTITY_UNITS", "split_unit", "normalize_unit",
           "unit_factor", "quantity_of_unit"]

# role (what a column is) -> the format's column name
ROLE_COLUMN = {"time": "time_s", "voltage": "voltage_V", "current": "current_A",
               "displacement": "displacement_mm", "force": "force_N", "gap": "gap_mm"}
ROLES = tuple(ROLE_COLUMN)
ROLE_QUANTITY = {"time": "time", "voltage": "voltage", "current": "current",
                 "displacement": "length", "gap": "length", "force": "force"}

# quantity -> {unit: factor to the format's unit}
QUANTITY_UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "sec": 1.0, "ms": 1e-3, "µs": 1e-6, "ns": 1e-9, "min": 60.0, "h": 3600.0},
    "voltage": {"V": 1.0, "mV": 1e-3, "µV": 1e-6, "kV": 1e3},
    "current": {"A": 1.0, "mA": 1e-3, "µA": 1e-6, "kA": 1e3},
    "length": {"mm": 1.0, "m": 1e3, "cm": 10.0, "µm": 1e-3, "nm": 1e-6, "in": 25.4},
    "force": {"N": 1.0, "mN": 1e-3, "µN": 1e-6, "kN": 1e3, "cN": 1e-2},
}
FORMAT_UNIT = {"time": "s", "voltage": "V", "current": "A", "length": "mm", "force": "N"}

_BRACKETED = re.compile(r"^(?P<base>.*?)\s*(?:\[\s*(?P<u1>[^\[\]]*?)\s*\]|\(\s*(?P<u2>[^()]*?)\s*\))\s*$")
_SUFFIXED = re.compile(r"^(?P<base>.+?)_(?P<u>[A-Za-zµμ]+)$")


def normalize_unit(unit: str) -> str:
    """Unit spelling normalized: Greek mu and a leading ``u`` before a unit letter become ``µ``."""
    u = unit.strip().replace("\u03bc", "\u00b5")
    if len(u) >= 2 and u[0] == "u" and u[1:] in ("s", "V", "A", "m", "N"):
        u = "\u00b5" + u[1:]
    return u


def quantity_of_unit(unit: str) -> str | None:
    """The quantity ("time", "length", ...) a unit belongs to, or None when unknown."""
    u = normalize_unit(unit)
    for q, units in QUANTITY_UNITS.items():
        if u in units:
            return q
    return None


def split_unit(name: str) -> tuple[str, str | None]:
    """``(base name, unit or None)`` of a header: ``"Time [s]"`` -> ``("Time", "s")``.

    Bracketed or parenthesized units are taken as written (even unknown ones, so that an
    unknown unit is reported rather than ignored); a ``_unit`` suffix only when it is a known unit.

    >>> split_unit("Current (mA)")
    ('Current', 'mA')
    >>> split_unit("current_mA")
    ('current', 'mA')
    >>> split_unit("Voltage")
    ('Voltage', None)
    """
    name = name.strip()
    m = _BRACKETED.match(name)
    if m and m.group("base"):
        u = m.group("u1") if m.group("u1") is not None else m.group("u2")
        return m.group("base").strip(), u
    m = _SUFFIXED.match(name)
    if m and quantity_of_unit(m.group("u")) is not None:
        return m.group("base"), m.group("u")
    return name, None


def unit_factor(unit: str, role: str, *, file=None, column: int | None = None, column_name: str | None = None,
                key: str | None = None) -> float:
    """Factor converting values in ``unit`` to the format's unit of ``role``.

    Raises LabImportError for an unknown unit or one of another dimension (e.g. mA for a
    displacement), naming the file, column and accepted units.

    >>> unit_factor("µm", "displacement")
    0.001
    """
    q = ROLE_QUANTITY[role]
    u = normalize_unit(unit)
    accepted = ", ".join(QUANTITY_UNITS[q])
    if u in QUANTITY_UNITS[q]:
        return QUANTITY_UNITS[q][u]
    other = quantity_of_unit(u)
    if other is not None:
        raise LabImportError(f"unit {unit!r} is a unit of {other}, but the {role} column needs a {q} unit "
                             f"({accepted}); converted to {FORMAT_UNIT[q]}", file=file, column=column,
                             column_name=column_name, key=key)
    raise LabImportError(f"unknown unit {unit!r} for the {role} column (accepted: {accepted})", file=file,
                         column=column, column_name=column_name, key=key)


def convert(values: np.ndarray, unit: str, role: str, **where) -> np.ndarray:
    """``values`` in ``unit`` converted to the format's unit of ``role`` (see :func:`unit_factor`)."""
    f = unit_factor(unit, role, **where)
    return np.asarray(values, dtype=float) * f if f != 1.0 else np.asarray(values, dtype=float)
