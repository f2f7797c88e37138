"""Import lab files into an ``mpc-actuator-data/1`` dataset: :func:`import_lab_files`."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.data.dataset import SWEEP_TESTS, DataFormatError, Dataset, GapSweep, Sample, TimeSeries, write_dataset
from harness.data.labimport.csvdialect import TextOptions, read_text_table
from harness.data.labimport.errors import LabImportError
from harness.data.labimport.lvm import read_lvm
from harness.data.labimport.mapping import (EXTENSION_TYPES, load_mapping, resolve_column, roles_for_test,
                                            test_settings)
from harness.data.labimport.matfile import read_mat
from harness.data.labimport.table import Table
from harness.data.labimport.tdms import read_tdms

__all__ = ["import_lab_files", "read_lab_file"]


def read_lab_file(path, settings: dict | None = None) -> Table:
    """Read one lab file with the reader its ``type`` (or extension) names.

    Parameters
    ----------
    path : path-like
        A text table (``.csv``, ``.tsv``, ``.txt``, ``.dat``, ``.asc``), ``.lvm``, ``.tdms`` or ``.mat``.
    settings : dict, optional
        A test's settings from the mapping (``type``, ``csv``, ``lvm``, ``tdms``).

    Returns
    -------
    Table

    Examples
    --------
    >>> read_lab_file("raw/t5.csv", {"csv": {"decimal": ","}}).names()     # doctest: +SKIP
    ['Zeit [s]', 'Strom (mA)', 'Weg [µm]']
    """
    settings = settings or {}
    file = Path(path)
    kind = settings.get("type") or EXTENSION_TYPES.get(file.suffix.lower())
    if kind is None:
        raise LabImportError(f"cannot tell the file type from the extension {file.suffix!r}; set 'type' "
                             f"(text, lvm, tdms, mat) in the mapping", file=file)
    if not file.is_file():
        raise LabImportError("file not found", file=file)
    if kind == "text":
        c = settings.get("csv", {})
        return read_text_table(file, TextOptions(delimiter=c.get("delimiter"), decimal=c.get("decimal"),
                                                 header_line=c.get("header_line"), encoding=c.get("encoding")))
    if kind == "lvm":
        c = settings.get("lvm", {})
        return read_lvm(file, segment=c.get("segment"), encoding=c.get("encoding"))
    if kind == "tdms":
        return read_tdms(file, group=settings.get("tdms", {}).get("group"))
    return read_mat(file)


def _check_time(t: np.ndarray, ch, table: Table, key: str) -> None:
    bad = np.nonzero(~(np.diff(t) > 0))[0]
    if bad.size:
        j = int(bad[0]) + 1
        line = int(ch.lines[j]) if ch is not None and ch.lines is not None else None
        raise LabImportError(f"time is not strictly increasing ({float(t[j - 1])!r} s then {float(t[j])!r} s, row {j + 1})",
                             file=table.file, line=line, column=None if ch is None else ch.column,
                             column_name=None if ch is None else ch.name, key=key)


def _build_test(test: str, spec: dict, table: Table, settings: dict, key: str):
    roles = roles_for_test(test)
    cols, src = {}, {}
    time_base = None
    if "time" in roles and "time" not in settings.get("columns", {}):
        # a time base defined by the file (LVM X0/Delta_X or X column, TDMS waveform) of the signal column
        for role in roles:
            ref = settings.get("columns", {}).get(role)
            if role != "time" and ref is not None:
                ch = table.find(ref, key=f"{key}.columns.{role}")
                if ch.time_s is not None:
                    time_base = ch.time_s
                    break
    for role in roles:
        cols[role], src[role] = resolve_column(table, role, settings, key, time_base=time_base)
    n = {r: v.size for r, v in cols.items()}
    if len(set(n.values())) != 1:
        raise LabImportError("columns differ in length: " + ", ".join(f"{r} {k}" for r, k in n.items()),
                             file=table.file, key=key)
    for role, v in cols.items():
        bad = np.nonzero(~np.isfinite(v))[0]
        if bad.size:
            ch = src[role]
            raise LabImportError(f"non-finite value in the {role} column (row {int(bad[0]) + 1})", file=table.file,
                                 column=None if ch is None else ch.column, column_name=None if ch is None else ch.name,
                                 line=None if ch is None or ch.lines is None else int(ch.lines[bad[0]]), key=key)
    if "time" in cols:
        _check_time(cols["time"], src["time"], table, key)
    kw = {"displacement_mm": cols.get("displacement"), "force_N": cols.get("force")}
    if test in SWEEP_TESTS:
        return GapSweep(test=test, file=None, gap_mm=cols["gap"], current_A=cols["current"],
                        field_T=float(spec["field_T"]), **kw)
    return TimeSeries(test=test, file=None, time_s=cols["time"], voltage_V=cols["voltage"], current_A=cols["current"],
                      field_T=float(spec["field_T"]), gap_mm=float(spec["gap_mm"]),
                      frequency_hz=float(spec["frequency_hz"]) if test == "T6" else None, **kw)


def import_lab_files(mapping_path_or_dict, out_dir, *, overwrite: bool = False) -> Path:
    """Import lab files named by a mapping into a new ``mpc-actuator-data/1`` dataset.

    The input files are opened read-only and never modified; everything is written into
    ``out_dir`` (by ``harness.data.dataset.write_dataset``, which validates the result and writes
    the manifest last). Units are converted to the format's (s, V, A, mm, N).

    Parameters
    ----------
    mapping_path_or_dict : path-like or dict
        The mapping (schema in :mod:`harness.data.labimport.mapping`): a JSON file (relative data
        paths start from its folder) or the same structure as a dict (paths from ``base_dir`` or
        the current folder).
    out_dir : path-like
        Output folder; must be new or empty (unless ``overwrite``), and must not hold any input file.
    overwrite : bool
        Replace the files of an earlier synthetic import in ``out_dir`` (measured data folders are
        never overwritten: ``write_dataset``'s rule).

    Returns
    -------
    Path
        The dataset folder, readable by ``harness.data.dataset.read_dataset``.

    Raises
    ------
    LabImportError
        Naming the file, line, column (or mapping key) and the problem.

    Examples
    --------
    >>> mapping = {"base_dir": "raw", "rig": {"coil_radius_mm": 15, "field_per_amp_T_per_A": 0.29},
    ...            "samples": [{"id": "W20-D45", "wt_pct": 20, "diameter_mm": 45, "thickness_mm": 1.5,
    ...                         "tests": {"T8": {"file": "t8.csv", "field_T": 0.23, "gap_mm": 2,
    ...                                          "columns": {"time": "Time [s]", "voltage": "U [V]",
    ...                                                      "current": "I (mA)", "force": "F [mN]"}}}}]}
    >>> import_lab_files(mapping, "imported")                           # doctest: +SKIP
    PosixPath('imported')
    """
    m, base, mfile = load_mapping(mapping_path_or_dict)
    out = Path(out_dir)
    out_r = out.resolve()
    defaults = m.get("defaults", {})
    plan = []
    for i, s in enumerate(m["samples"]):
        for test, spec in s["tests"].items():
            path = Path(spec["file"])
            path = path if path.is_absolute() else base / path
            if path.resolve() == out_r or path.resolve().is_relative_to(out_r):
                raise LabImportError(f"the output folder {out} holds this input file; name another output folder",
                                     file=path, key=f"samples[{i}].tests.{test}.file")
            plan.append((i, s, test, spec, path))
    if mfile is not None and mfile.resolve().is_relative_to(out_r):
        raise LabImportError(f"the output folder {out} holds the mapping file; name another output folder", file=mfile)
    if out.exists() and (not out.is_dir() or any(out.iterdir())) and not overwrite:
        raise LabImportError(f"the output folder {out} is not empty (or not a folder); name a new or empty folder "
                             f"(or pass overwrite=True to replace an earlier import)", file=out)
    tables: dict = {}
    samples = {}
    for i, s, test, spec, path in plan:
        key = f"samples[{i}].tests.{test}"
        settings = test_settings(defaults, spec)
        tkey = (str(path.resolve()), repr(sorted((k, repr(v)) for k, v in settings.items() if k in
                                                 ("type", "csv", "lvm", "tdms"))))
        if tkey not in tables:
            tables[tkey] = read_lab_file(path, settings)
        obj = _build_test(test, spec, tables[tkey], settings, key)
        samples.setdefault(i, {})[test] = obj
    out_samples = []
    for i, s in enumerate(m["samples"]):
        tests = {t: samples[i][t] for t in sorted(samples[i])}
        out_samples.append(Sample(id=s["id"], wt_pct=float(s["wt_pct"]), diameter_mm=float(s["diameter_mm"]),
                                  thickness_mm=float(s["thickness_mm"]), tests=tests))
    rig = dict(m.get("rig", {}))
    rig["imported_from"] = {s["id"]: {t: str(spec["file"]) for t, spec in s["tests"].items()} for s in m["samples"]}
    ds = Dataset(root=None, synthetic=bool(m.get("synthetic", False)),
                 description=m.get("description", "") or "imported from lab files by mpc-actuator import",
                 rig=rig, samples=out_samples)
    try:
        return write_dataset(ds, out, overwrite=overwrite)
    except FileExistsError as e:
        raise LabImportError(str(e), file=out) from None
    except DataFormatError as e:
        raise LabImportError(f"the imported data do not form a valid dataset: {e}", file=mfile) from None
