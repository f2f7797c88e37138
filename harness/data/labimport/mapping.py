"""The mapping file of the lab import: which file and column is which, and the manifest metadata.

Schema (JSON object; units in every key that holds a quantity; unknown keys are errors):

``format``          optional, ``"mpc-actuator-labimport/1"``
``synthetic``       optional bool (default false: measured data)
``description``     optional string, copied to the manifest
``base_dir``        optional folder that relative ``file`` paths start from (default: the mapping
                    file's folder; the current folder for a mapping given as a dict)
``rig``             optional object copied to the manifest's ``rig``: ``coil_radius_mm`` (> 0),
                    ``field_per_amp_T_per_A`` (> 0), ``sweep_average_s`` (> 0, how long each sweep
                    point was averaged), ``sensors`` (object), any other keys kept as they are
``defaults``        optional test settings (``columns``, ``units``, ``negate``, ``csv``, ``lvm``,
                    ``tdms``, ``type``) applied to every test unless the test sets them
``samples[]``       ``id``, ``wt_pct``, ``diameter_mm``, ``thickness_mm``, ``tests``
``samples[].tests.Tn``  ``file`` (path), ``field_T``; T2-T6 and T8 ``gap_mm``; T6 ``frequency_hz``;
                    ``columns``: {role: column}, roles ``time``, ``voltage``, ``current``,
                    ``displacement``, ``force``, ``gap`` (those the test needs, see the format); a
                    column is a header name (with or without its unit), a 1-based column number, a
                    channel (TDMS ``"Group/Channel"``, MAT variable or ``"matrix:k"``); ``time`` may be
                    left out when the file defines the time base (LVM X0/Delta_X, TDMS waveforms);
                    ``units``: {role: unit} where the header or channel has none (or to override it);
                    ``negate``: [roles] whose sign is flipped (e.g. a laser counting away from the coil);
                    ``type``: ``"text"``, ``"lvm"``, ``"tdms"`` or ``"mat"`` (default from the extension);
                    ``csv``: {``delimiter``, ``decimal``, ``header_line``, ``encoding``};
                    ``lvm``: {``segment``, ``encoding``}; ``tdms``: {``group``}

Example::

    {"rig": {"coil_radius_mm": 15, "field_per_amp_T_per_A": 0.29},
     "samples": [{"id": "W20-D45", "wt_pct": 20, "diameter_mm": 45, "thickness_mm": 1.5,
       "tests": {"T5": {"file": "raw/t5.csv", "field_T": 0.23, "gap_mm": 5,
                        "columns": {"time": "Time [s]", "voltage": "U [V]", "current": "Current (mA)",
                                    "displacement": "Displacement [µm]"}}}}]}
"""
from __future__ import annotations

import difflib
import json
import math
from pathlib import Path

import numpy as np

from harness.data.dataset import COLUMNS, REQUIRED_TEST_KEYS, SWEEP_TESTS, TESTS
from harness.data.labimport.errors import LabImportError
from harness.data.labimport.units import ROLE_COLUMN, ROLES, convert

__all__ = ["MAPPING_FORMAT", "load_mapping", "TOP_KEYS", "TEST_KEYS", "roles_for_test", "test_settings",
           "resolve_column"]

MAPPING_FORMAT = "mpc-actuator-labimport/1"
TOP_KEYS = ("format", "synthetic", "description", "base_dir", "rig", "defaults", "samples")
SAMPLE_KEYS = ("id", "wt_pct", "diameter_mm", "thickness_mm", "tests")
SETTING_KEYS = ("columns", "units", "negate", "type", "csv", "lvm", "tdms")
TEST_KEYS = ("file", "field_T", "gap_mm", "frequency_hz") + SETTING_KEYS
SUB_KEYS = {"csv": ("delimiter", "decimal", "header_line", "encoding"), "lvm": ("segment", "encoding"),
            "tdms": ("group",)}
TYPES = ("text", "lvm", "tdms", "mat")
EXTENSION_TYPES = {".csv": "text", ".tsv": "text", ".txt": "text", ".dat": "text", ".asc": "text",
                   ".lvm": "lvm", ".tdms": "tdms", ".mat": "mat"}


def roles_for_test(test: str) -> tuple[str, ...]:
    """Roles a test needs, from the format's columns (``time_s`` -> ``time``)."""
    back = {v: k for k, v in ROLE_COLUMN.items()}
    return tuple(back[c] for c in COLUMNS[test])


def _unknown(d: dict, allowed, where: str, file) -> None:
    for k in d:
        if k not in allowed:
            close = difflib.get_close_matches(str(k), allowed, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise LabImportError(f"unknown key {k!r}{hint}; allowed: {', '.join(allowed)}", file=file,
                                 key=f"{where}.{k}" if where else str(k))


def _number(v, key: str, file, *, positive=False, lo=None, hi=None) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise LabImportError(f"must be a finite number, got {v!r}", file=file, key=key)
    if positive and v <= 0:
        raise LabImportError(f"must be > 0, got {v!r}", file=file, key=key)
    if lo is not None and v < lo or hi is not None and v > hi:
        raise LabImportError(f"must be in [{lo}, {hi}], got {v!r}", file=file, key=key)
    return float(v)


def load_mapping(mapping) -> tuple[dict, Path, Path | None]:
    """(validated mapping, base folder, mapping file or None) from a path or a dict."""
    if isinstance(mapping, dict):
        m, mfile = mapping, None
        base = Path.cwd()
    else:
        mfile = Path(mapping)
        try:
            with open(mfile, "r", encoding="utf-8-sig") as fh:
                m = json.load(fh)
        except FileNotFoundError:
            raise LabImportError("mapping file not found", file=mfile) from None
        except json.JSONDecodeError as e:
            raise LabImportError(f"invalid JSON: {e.msg}", file=mfile, line=e.lineno, column=e.colno) from None
        base = mfile.parent
        if not isinstance(m, dict):
            raise LabImportError("the mapping must be a JSON object", file=mfile)
    _validate(m, mfile)
    if "base_dir" in m:
        b = Path(m["base_dir"])
        base = b if b.is_absolute() else base / b
    return m, base, mfile


def _validate(m: dict, f) -> None:
    _unknown(m, TOP_KEYS, "", f)
    if "format" in m and m["format"] != MAPPING_FORMAT:
        raise LabImportError(f"format must be {MAPPING_FORMAT!r}, got {m['format']!r}", file=f, key="format")
    if "synthetic" in m and not isinstance(m["synthetic"], bool):
        raise LabImportError("must be true or false", file=f, key="synthetic")
    for k in ("description", "base_dir"):
        if k in m and not isinstance(m[k], str):
            raise LabImportError("must be a string", file=f, key=k)
    rig = m.get("rig", {})
    if not isinstance(rig, dict):
        raise LabImportError("must be an object", file=f, key="rig")
    for k in ("coil_radius_mm", "field_per_amp_T_per_A", "sweep_average_s"):
        if k in rig:
            _number(rig[k], f"rig.{k}", f, positive=True)
    if "sensors" in rig and not isinstance(rig["sensors"], dict):
        raise LabImportError("must be an object", file=f, key="rig.sensors")
    defaults = m.get("defaults", {})
    if not isinstance(defaults, dict):
        raise LabImportError("must be an object", file=f, key="defaults")
    _unknown(defaults, SETTING_KEYS, "defaults", f)
    _validate_settings(defaults, "defaults", f)
    samples = m.get("samples")
    if not isinstance(samples, list) or not samples:
        raise LabImportError("must be a non-empty list of samples", file=f, key="samples")
    ids = set()
    for i, s in enumerate(samples):
        w = f"samples[{i}]"
        if not isinstance(s, dict):
            raise LabImportError("must be an object", file=f, key=w)
        _unknown(s, SAMPLE_KEYS, w, f)
        for k in SAMPLE_KEYS:
            if k not in s:
                raise LabImportError("missing key", file=f, key=f"{w}.{k}")
        if not isinstance(s["id"], str) or not s["id"]:
            raise LabImportError("must be a non-empty string", file=f, key=f"{w}.id")
        if s["id"] in ids:
            raise LabImportError(f"duplicate sample id {s['id']!r}", file=f, key=f"{w}.id")
        ids.add(s["id"])
        _number(s["wt_pct"], f"{w}.wt_pct", f, lo=0, hi=100)
        _number(s["diameter_mm"], f"{w}.diameter_mm", f, positive=True)
        _number(s["thickness_mm"], f"{w}.thickness_mm", f, positive=True)
        if not isinstance(s["tests"], dict) or not s["tests"]:
            raise LabImportError("must be a non-empty object {test: ...}", file=f, key=f"{w}.tests")
        for t, spec in s["tests"].items():
            wt = f"{w}.tests.{t}"
            if t not in TESTS:
                raise LabImportError(f"unknown test {t!r} (known: {', '.join(TESTS)})", file=f, key=wt)
            if not isinstance(spec, dict):
                raise LabImportError("must be an object", file=f, key=wt)
            _unknown(spec, TEST_KEYS, wt, f)
            if not isinstance(spec.get("file"), str) or not spec.get("file"):
                raise LabImportError("missing or empty 'file'", file=f, key=f"{wt}.file")
            for k in REQUIRED_TEST_KEYS[t]:
                if k not in spec:
                    raise LabImportError(f"missing key (test {t} needs {', '.join(REQUIRED_TEST_KEYS[t])})", file=f,
                                         key=f"{wt}.{k}")
            for k in ("field_T", "frequency_hz"):
                if k in spec:
                    _number(spec[k], f"{wt}.{k}", f, positive=True)
            if "gap_mm" in spec:
                _number(spec["gap_mm"], f"{wt}.gap_mm", f, lo=0)
                if t in SWEEP_TESTS:
                    raise LabImportError(f"{t} is a gap sweep: its gaps come from the gap column", file=f,
                                         key=f"{wt}.gap_mm")
            _validate_settings(spec, wt, f)


def _validate_settings(d: dict, where: str, f) -> None:
    for k in ("columns", "units"):
        if k in d:
            if not isinstance(d[k], dict):
                raise LabImportError("must be an object {role: ...}", file=f, key=f"{where}.{k}")
            _unknown(d[k], ROLES, f"{where}.{k}", f)
    for role, u in d.get("units", {}).items():
        if not isinstance(u, str):
            raise LabImportError("a unit is a string", file=f, key=f"{where}.units.{role}")
    if "negate" in d:
        if not isinstance(d["negate"], list) or any(r not in ROLES for r in d["negate"]):
            raise LabImportError(f"must be a list of roles ({', '.join(ROLES)})", file=f, key=f"{where}.negate")
    if "type" in d and d["type"] not in TYPES:
        raise LabImportError(f"must be one of {', '.join(TYPES)}", file=f, key=f"{where}.type")
    for k, allowed in SUB_KEYS.items():
        if k in d:
            if not isinstance(d[k], dict):
                raise LabImportError("must be an object", file=f, key=f"{where}.{k}")
            _unknown(d[k], allowed, f"{where}.{k}", f)


def test_settings(defaults: dict, spec: dict) -> dict:
    """A test's settings: the defaults, with ``columns``/``units``/``csv``/... merged key by key."""
    out = {}
    for k in SETTING_KEYS:
        d, s = defaults.get(k), spec.get(k)
        if isinstance(d, dict) or isinstance(s, dict):
            out[k] = {**(d or {}), **(s or {})}
        elif s is not None or d is not None:
            out[k] = s if s is not None else d
    return out


def resolve_column(table, role: str, settings: dict, key: str, time_base: np.ndarray | None = None):
    """Values of ``role`` in the format's unit, and the channel they came from (None for a time base
    the file defines). LabImportError naming file, column and problem."""
    ref = settings.get("columns", {}).get(role)
    if ref is None:
        if role == "time" and time_base is not None:
            return np.asarray(time_base, dtype=float), None
        raise LabImportError(f"no column mapped for {role!r} (set columns.{role}; the file has: "
                             f"{', '.join(repr(n) for n in table.names())})", file=table.file, key=key)
    ch = table.find(ref, key=f"{key}.columns.{role}")
    unit = settings.get("units", {}).get(role) or ch.unit
    if unit is None:
        raise LabImportError(f"no unit for the {role} column: write it in the header ('Name [unit]') or give "
                             f"units.{role} in the mapping", file=table.file, column=ch.column,
                             column_name=ch.name, key=key)
    vals = convert(ch.values, unit, role, file=table.file, column=ch.column, column_name=ch.name,
                   key=f"{key}.columns.{role}")
    if role in settings.get("negate", []):
        vals = -vals
    return vals, ch
