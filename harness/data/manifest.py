"""Reading and checking ``manifest.json`` of an ``mpc-actuator-data/1`` dataset.

:func:`load_manifest_json` parses the file (UTF-8, no duplicate keys) and
:class:`ManifestChecker` checks the parsed object, collecting every problem as a
:class:`~harness.data.format.DataFormatError` naming the file and the JSON path.
"""
from __future__ import annotations

import difflib
import json
import math
import re
from pathlib import Path

from harness.data.format import FORMAT, REQUIRED_TEST_KEYS, TESTS, DataFormatError

__all__ = ["ManifestChecker", "load_manifest_json", "json_path"]

_TOP_KEYS = ("format", "synthetic", "description", "rig", "samples")
_SAMPLE_KEYS = ("id", "wt_pct", "diameter_mm", "thickness_mm", "tests")


def json_path(parts) -> str:
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


class ManifestChecker:
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
        self.problems.append(DataFormatError(msg, file=self.mfile, key=json_path(parts) or None))

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
                # timing conventions (harness.data.protocol.sweep_timing); absent = from the data
                dt = self.number(rig, "sample_period_s", ["rig"], lo=0, lo_open=True, optional=True)
                hold = self.number(rig, "sweep_hold_s", ["rig"], lo=0, lo_open=True, optional=True)
                avg = self.number(rig, "sweep_average_s", ["rig"], lo=0, lo_open=True, optional=True)
                if avg is not None and hold is not None and avg > hold:
                    self.err(["rig", "sweep_average_s"], f"sweep_average_s must be <= rig.sweep_hold_s "
                                                         f"({hold:g} s), got {avg:g}")
                if avg is not None and dt is not None and avg < dt * (1 - 1e-9):
                    self.err(["rig", "sweep_average_s"], f"sweep_average_s must be at least one sample period "
                                                         f"(rig.sample_period_s = {dt:g} s; a single reading: "
                                                         f"one period), got {avg:g}")
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
        out = {"key": json_path(parts)}
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


def load_manifest_json(mfile: Path):
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


