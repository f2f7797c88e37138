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

The format is split by concern: :mod:`harness.data.format` (name, test tables, errors),
:mod:`harness.data.records` (the dataclasses), :mod:`harness.data.manifest` (manifest
checks), :mod:`harness.data.csvfile` (CSV checks), :mod:`harness.data.writer`; this module
reads a dataset and re-exports the public API (import it from here).
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable

from harness.data.csvfile import build_test, read_csv
from harness.data.format import (
    COLUMNS, FORMAT, MANIFEST, REQUIRED_TEST_KEYS, SWEEP_TESTS, TEST_DESCRIPTIONS, TESTS, TIME_SERIES_TESTS,
    DataFormatError, UnknownSampleError, combine_problems,
)
from harness.data.manifest import ManifestChecker, load_manifest_json
from harness.data.records import Dataset, GapSweep, Sample, TimeSeries
from harness.data.writer import write_dataset

__all__ = [
    "FORMAT", "MANIFEST", "TESTS", "TIME_SERIES_TESTS", "SWEEP_TESTS", "COLUMNS", "TEST_DESCRIPTIONS",
    "REQUIRED_TEST_KEYS", "DataFormatError", "UnknownSampleError",
    "TimeSeries", "GapSweep", "Sample", "Dataset",
    "read_dataset", "write_dataset", "dataset_summary",
]


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

    Parameters
    ----------
    path : str or Path
        The dataset folder, or its manifest.json.
    tests : iterable of str or None
        Test names every selected sample must have (validate mode, e.g. ``["T3", "T5", "T8"]``).
    samples : iterable of str or None
        Ids of the samples to load (manifest order is kept; unknown ids are an error); None: all.

    Returns
    -------
    Dataset
        The samples with their tests (``TimeSeries`` or ``GapSweep`` per test), the rig and the manifest.

    Raises
    ------
    DataFormatError
        Naming file, line, column or JSON key of every problem found.
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
    m = ManifestChecker(load_manifest_json(mfile), mfile)
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
                try:                        # read in blocks: the file is never held whole
                    with open(target, "rb") as fh:
                        cols = read_csv(fh, name, display)
                except OSError as ex:
                    raise DataFormatError(f"cannot read: {ex.strerror or ex}", file=display) from None
                tests_out[name] = build_test(name, cols, te, display)
            except DataFormatError as ex:
                problems.append(ex)
        out_samples.append(Sample(id=e["id"], wt_pct=e["wt_pct"], diameter_mm=e["diameter_mm"],
                                  thickness_mm=e["thickness_mm"], tests=tests_out))
    if problems:
        raise combine_problems(problems, f"dataset {root}")
    # provenance (read_from): write_dataset never writes over this folder
    ds = Dataset(root=root, synthetic=m.synthetic, description=m.description, rig=m.rig, samples=out_samples,
                 read_from=root_resolved)
    return ds


# ====================================================================== summary
def dataset_summary(ds: Dataset) -> str:
    """A few human-readable lines: data kind, rig, samples and their tests.

    Parameters
    ----------
    ds : Dataset
        A dataset read by :func:`read_dataset`.

    Returns
    -------
    str
        The summary ``mpc-actuator check`` prints.
    """
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
