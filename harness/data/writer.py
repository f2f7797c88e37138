"""Writing an ``mpc-actuator-data/1`` dataset: :func:`write_dataset` (validated first, atomic files,
never over the folder a dataset was read from nor over measured data)."""
from __future__ import annotations

import json
import os
import re
import tempfile
from pathlib import Path

import numpy as np

from harness.data.csvfile import parse_csv
from harness.data.format import (
    COLUMNS, FORMAT, MANIFEST, REQUIRED_TEST_KEYS, SWEEP_TESTS, TESTS, DataFormatError, combine_problems,
)
from harness.data.manifest import ManifestChecker
from harness.data.records import Dataset, GapSweep, Sample, TimeSeries

__all__ = ["write_dataset"]


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
    if isinstance(t, TimeSeries) and "frequency_hz" not in REQUIRED_TEST_KEYS[name] and t.frequency_hz is not None:
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
    protected = [p for p in (getattr(ds, "read_from", None),) if p is not None]
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
                if "frequency_hz" in REQUIRED_TEST_KEYS[name]:
                    entry["frequency_hz"] = t.frequency_hz
            tests[name] = entry
            text = _csv_text(ds, s, name, t)
            try:
                parse_csv(text, name, out / rel)
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
    problems.extend(ManifestChecker(plain, mfile).problems)
    if problems:
        raise combine_problems(problems, f"dataset to be written to {out}")
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


