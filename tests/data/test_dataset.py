"""Tests of harness.data.dataset (format mpc-actuator-data/1).

A small valid dataset is written by hand (not by the writer) in a fixture; each
error test breaks it in exactly one way and checks that the message names the
file and the line/column or JSON key.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from harness.data.dataset import (
    COLUMNS, FORMAT, SWEEP_TESTS, TEST_DESCRIPTIONS, TIME_SERIES_TESTS, DataFormatError, Dataset,
    GapSweep, Sample, TimeSeries, UnknownSampleError, dataset_summary, read_dataset, write_dataset,
)

S1, S2 = "W20-D45", "W30-D60"

FILES = {
    f"{S1}/T1.csv": "# T1 gap sweep\ngap_mm,current_A,displacement_mm\n10,0.79,1.5\n5,0.79,3.25\n0,0.8,4.0\n",
    f"{S1}/T3.csv": ("time_s,voltage_V,current_A,displacement_mm\n"
                     "0.0,0.0,0.0,0.0\n0.001,6.0,0.1,0.01\n0.002,6.0,0.2,0.05\n0.003,6.0,0.3,0.1\n"),
    f"{S1}/T6.csv": "time_s,voltage_V,current_A,displacement_mm\n0,0,0,0\n0.5,12,0.8,2.5\n1.0,0,0.01,0.1\n",
    f"{S1}/T7.csv": "gap_mm,current_A,force_N\n0,0.8,0.31\n4,0.8,0.12\n",
    f"{S1}/T8.csv": "time_s,voltage_V,current_A,force_N\n0,0,0,0\n0.001,12,0.4,0.05\n0.002,12,0.7,0.2\n",
    f"{S2}/T1.csv": "gap_mm,current_A,displacement_mm\n8,0.79,2.0\n",
    f"{S2}/T3.csv": "time_s,voltage_V,current_A,displacement_mm\n0,0,0,0\n0.01,6,0.2,0.3\n",
}


def manifest_dict():
    return {
        "format": FORMAT, "synthetic": True, "description": "hand-written test data",
        "rig": {"coil_radius_mm": 15.0, "field_per_amp_T_per_A": 0.29, "sensors": {"laser": "x"}},
        "samples": [
            {"id": S1, "wt_pct": 20, "diameter_mm": 45, "thickness_mm": 1.5, "tests": {
                "T1": {"file": f"{S1}/T1.csv", "field_T": 0.23},
                "T3": {"file": f"{S1}/T3.csv", "field_T": 0.11, "gap_mm": 9.0},
                "T6": {"file": f"{S1}/T6.csv", "field_T": 0.23, "gap_mm": 10.0, "frequency_hz": 1.0},
                "T7": {"file": f"{S1}/T7.csv", "field_T": 0.23},
                "T8": {"file": f"{S1}/T8.csv", "field_T": 0.23, "gap_mm": 2.0}}},
            {"id": S2, "wt_pct": 30, "diameter_mm": 60, "thickness_mm": 1.5, "tests": {
                "T1": {"file": f"{S2}/T1.csv", "field_T": 0.23},
                "T3": {"file": f"{S2}/T3.csv", "field_T": 0.11, "gap_mm": 12.0}}},
        ],
    }


def write_manifest(root: Path, m) -> None:
    text = m if isinstance(m, str) else json.dumps(m, indent=2)
    (root / "manifest.json").write_text(text)


@pytest.fixture
def ds_dir(tmp_path) -> Path:
    root = tmp_path / "ds"
    for rel, text in FILES.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    write_manifest(root, manifest_dict())
    return root


def put(root: Path, rel: str, text: str) -> Path:
    (root / rel).write_text(text)
    return root / rel


def edit_manifest(root: Path, fn) -> None:
    m = manifest_dict()
    fn(m)
    write_manifest(root, m)


def fails(root, *fragments, **kw) -> DataFormatError:
    with pytest.raises(DataFormatError) as ei:
        read_dataset(root, **kw)
    msg = str(ei.value)
    for f in fragments:
        assert f in msg, f"{f!r} not in message:\n{msg}"
    return ei.value


# ------------------------------------------------------------------ valid data
def test_reads_valid_dataset(ds_dir):
    ds = read_dataset(ds_dir)
    assert ds.synthetic is True and ds.description == "hand-written test data"
    assert ds.field_per_amp_T_per_A == 0.29 and ds.coil_radius_mm == 15.0
    assert ds.rig["sensors"] == {"laser": "x"}            # extra rig keys kept
    assert [s.id for s in ds.samples] == [S1, S2]
    s = ds.sample(S1)
    assert (s.wt_pct, s.diameter_mm, s.thickness_mm) == (20.0, 45.0, 1.5)
    assert list(s.tests) == ["T1", "T3", "T6", "T7", "T8"]
    t1, t3, t6, t7, t8 = (s.tests[k] for k in ("T1", "T3", "T6", "T7", "T8"))
    assert isinstance(t1, GapSweep) and t1.force_N is None and t1.field_T == 0.23
    np.testing.assert_array_equal(t1.gap_mm, [10, 5, 0])          # file order kept
    np.testing.assert_array_equal(t1.displacement_mm, [1.5, 3.25, 4.0])
    assert isinstance(t3, TimeSeries) and t3.force_N is None and t3.frequency_hz is None
    assert (t3.field_T, t3.gap_mm) == (0.11, 9.0) and t3.time_s.dtype == np.float64
    assert t6.frequency_hz == 1.0 and t6.gap_mm == 10.0
    assert isinstance(t7, GapSweep) and t7.displacement_mm is None
    np.testing.assert_array_equal(t7.force_N, [0.31, 0.12])
    assert t8.displacement_mm is None and t8.gap_mm == 2.0
    assert t8.file == ds_dir / S1 / "T8.csv"


def test_constants_consistent():
    assert set(COLUMNS) == set(TIME_SERIES_TESTS) | set(SWEEP_TESTS) == set(TEST_DESCRIPTIONS)
    assert COLUMNS["T7"] == ("gap_mm", "current_A", "force_N")
    assert COLUMNS["T8"] == ("time_s", "voltage_V", "current_A", "force_N")
    assert "0.06 T" in TEST_DESCRIPTIONS["T2"] and "1 Hz" in TEST_DESCRIPTIONS["T6"]


def test_optional_rig_values_absent(ds_dir):
    edit_manifest(ds_dir, lambda m: m.update(rig={"effects": {}}))
    ds = read_dataset(ds_dir)
    assert ds.field_per_amp_T_per_A is None and ds.coil_radius_mm is None
    assert ds.rig == {"effects": {}}


def test_comments_blank_lines_and_extra_columns_accepted(ds_dir):
    put(ds_dir, f"{S1}/T3.csv",
        "# recorded 2024-01-01\n\n  # operator: X\n"
        "note,displacement_mm,time_s,current_A,voltage_V,temp_C\n"
        "start,0,0,0,0,21.5\n# pause\n\nramp up,0.01,0.001,0.1,6,n/a\n,0.05,0.002,0.2,6,\r\n")
    t3 = read_dataset(ds_dir).sample(S1).tests["T3"]
    np.testing.assert_array_equal(t3.time_s, [0, 0.001, 0.002])
    np.testing.assert_array_equal(t3.voltage_V, [0, 6, 6])
    np.testing.assert_array_equal(t3.displacement_mm, [0, 0.01, 0.05])


def test_manifest_path_accepted(ds_dir):
    assert read_dataset(ds_dir / "manifest.json") == read_dataset(ds_dir)


def test_reader_does_not_modify_files(ds_dir):
    def snapshot():   # every file and folder: bytes and mtime (also catches new files)
        return {p: (p.is_file() and p.read_bytes(), p.stat().st_mtime_ns) for p in ds_dir.rglob("*")}
    before = snapshot()
    read_dataset(ds_dir, tests=("T1",))
    assert snapshot() == before
    put(ds_dir, f"{S2}/T1.csv", "gap_mm,current_A,displacement_mm\n")   # a failing read too
    before = snapshot()
    with pytest.raises(DataFormatError):
        read_dataset(ds_dir)
    assert snapshot() == before


# ------------------------------------------------------------------ writer
def test_round_trip(ds_dir, tmp_path):
    ds = read_dataset(ds_dir)
    out = write_dataset(ds, tmp_path / "copy")
    back = read_dataset(out)
    assert back == ds and back.root == tmp_path / "copy"
    text = (out / S1 / "T3.csv").read_text()
    assert text.startswith("# synthetic data")
    m = json.loads((out / "manifest.json").read_text())
    assert m["format"] == FORMAT and m["samples"][0]["wt_pct"] == 20
    assert m["rig"]["sensors"] == {"laser": "x"}


def test_round_trip_in_memory_exact_floats(tmp_path):
    t = np.array([0.0, 0.1 + 0.2, 1.0 / 3.0])
    ts = TimeSeries("T6", None, t, [0, 1e-300, -2.5e7], [1 / 7, 2 / 7, 3 / 7], [0.1, 0.2, np.pi], None,
                    0.23, 10.5, 1.0)
    gs = GapSweep("T7", None, [3, 1, 2], [0.8, 0.8, 0.8], None, [0.1, 0.5, 0.3], 0.23)
    ds = Dataset(root=None, synthetic=False, description="x", rig={},
                 samples=[Sample("odd/id ..", 12.5, 30, 1.5, {"T6": ts, "T7": gs})])
    out = write_dataset(ds, tmp_path / "o")
    assert not (out / "S1.csv").exists() and "# synthetic" not in next(out.rglob("T6.csv")).read_text()
    back = read_dataset(out)
    assert back == ds
    assert back != Dataset(None, False, "x", {}, [Sample("odd/id ..", 12.5, 30, 1.5, {"T7": gs})])


def test_write_refuses_non_empty_folder(ds_dir, tmp_path):
    ds = read_dataset(ds_dir)
    out = tmp_path / "busy"
    out.mkdir()
    (out / "keep.txt").write_text("hello")
    with pytest.raises(FileExistsError, match="busy"):
        write_dataset(ds, out)
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    write_dataset(ds, out, overwrite=True)
    assert read_dataset(out) == ds and (out / "keep.txt").read_text() == "hello"


def test_write_refuses_source_folder(ds_dir):
    ds = read_dataset(ds_dir)
    before = {p: p.read_bytes() for p in ds_dir.rglob("*") if p.is_file()}
    for target in (ds_dir, ds_dir / S1, ds_dir.parent):
        with pytest.raises(DataFormatError, match="read from"):
            write_dataset(ds, target, overwrite=True)
    assert {p: p.read_bytes() for p in ds_dir.rglob("*") if p.is_file()} == before


def test_write_never_overwrites_measured_data(ds_dir, tmp_path):
    out = tmp_path / "measured"
    out.mkdir()
    (out / "manifest.json").write_text(json.dumps({**manifest_dict(), "synthetic": False}))
    with pytest.raises(FileExistsError, match="measured"):
        write_dataset(read_dataset(ds_dir), out, overwrite=True)


def test_write_validates_before_writing(tmp_path):
    bad = TimeSeries("T3", None, [0.0, 0.0], [1, 1], [1, 1], [0, 1], None, 0.11, 9.0)
    ds = Dataset(None, True, "", {}, [Sample("A", 20, 45, 1.5, {"T3": bad})])
    with pytest.raises(DataFormatError, match="strictly increasing"):
        write_dataset(ds, tmp_path / "o")
    short = TimeSeries("T3", None, [0.0, 1.0], [1, 1], [1], [0, 1], None, 0.11, 9.0)
    with pytest.raises(DataFormatError, match="differ in length"):
        write_dataset(Dataset(None, True, "", {}, [Sample("A", 20, 45, 1.5, {"T3": short})]), tmp_path / "o")
    assert not (tmp_path / "o").exists()


def test_summary(ds_dir):
    text = dataset_summary(read_dataset(ds_dir))
    assert "SYNTHETIC" in text and "2 sample" in text and "0.29 T/A" in text
    assert f"{S1}: 20 wt%" in text and "T1(3 gaps)" in text and "T8(3 pts)" in text


# ------------------------------------------------------------------ manifest errors
def test_manifest_not_found(tmp_path):
    (tmp_path / "empty").mkdir()
    fails(tmp_path / "empty", "manifest.json", "not found")
    fails(tmp_path / "nope", "nope", "not found")


def test_invalid_json_names_line(ds_dir):
    write_manifest(ds_dir, '{\n  "format": "mpc-actuator-data/1",\n  "synthetic": true,,\n}')
    e = fails(ds_dir, "manifest.json", "line 3", "invalid JSON")
    assert e.line == 3


@pytest.mark.parametrize("fmt, fragment", [(None, "missing required key 'format'"),
                                           ("mpc-actuator-data/2", "unsupported format")])
def test_wrong_or_missing_format(ds_dir, fmt, fragment):
    edit_manifest(ds_dir, lambda m: m.pop("format") if fmt is None else m.update(format=fmt))
    fails(ds_dir, "manifest.json", fragment, FORMAT)


def test_missing_required_key_names_json_path(ds_dir):
    edit_manifest(ds_dir, lambda m: m["samples"][1]["tests"]["T3"].pop("gap_mm"))
    e = fails(ds_dir, "manifest.json", "samples[1].tests.T3.gap_mm", "missing required key 'gap_mm'")
    assert e.key == "samples[1].tests.T3.gap_mm"


def test_t6_needs_frequency_and_misspelt_key_is_suggested(ds_dir):
    def f(m):
        t6 = m["samples"][0]["tests"]["T6"]
        t6["frequency_Hz"] = t6.pop("frequency_hz")
    edit_manifest(ds_dir, f)
    fails(ds_dir, "samples[0].tests.T6.frequency_hz", "did you mean 'frequency_hz'?")


@pytest.mark.parametrize("where, key, value, fragment", [
    ("sample", "wt_pct", "20", "wt_pct must be a number, got string"),
    ("sample", "diameter_mm", True, "diameter_mm must be a number, got boolean"),
    ("sample", "thickness_mm", -1.5, "thickness_mm must be > 0"),
    ("top", "synthetic", "yes", "synthetic must be true or false"),
    ("top", "samples", {}, "samples must be an array"),
])
def test_wrong_types(ds_dir, where, key, value, fragment):
    edit_manifest(ds_dir, lambda m: (m if where == "top" else m["samples"][1]).__setitem__(key, value))
    path = key if where == "top" else f"samples[1].{key}"
    fails(ds_dir, "manifest.json", path, fragment)


def test_duplicate_sample_ids(ds_dir):
    edit_manifest(ds_dir, lambda m: m["samples"][1].update(id=S1))
    fails(ds_dir, "manifest.json", "samples[1].id", f"duplicate sample id '{S1}'", "samples[0]")


def test_unknown_test(ds_dir):
    edit_manifest(ds_dir, lambda m: m["samples"][0]["tests"].update(T9={"file": f"{S1}/T1.csv", "field_T": 1}))
    fails(ds_dir, "manifest.json", "samples[0].tests.T9", "unknown test 'T9'")


@pytest.mark.parametrize("rel, fragment", [(f"{S1}/T33.csv", "does not exist"),
                                           ("../outside.csv", "outside the dataset folder"),
                                           ("/etc/passwd", "absolute path")])
def test_bad_file_reference(ds_dir, rel, fragment):
    (ds_dir.parent / "outside.csv").write_text(FILES[f"{S1}/T3.csv"])
    edit_manifest(ds_dir, lambda m: m["samples"][0]["tests"]["T3"].update(file=rel))
    fails(ds_dir, "manifest.json", "samples[0].tests.T3.file", fragment)


def test_symlink_escaping_folder_rejected(ds_dir):
    (ds_dir.parent / "outside.csv").write_text(FILES[f"{S1}/T3.csv"])
    os.symlink(ds_dir.parent / "outside.csv", ds_dir / S1 / "link.csv")
    edit_manifest(ds_dir, lambda m: m["samples"][0]["tests"]["T3"].update(file=f"{S1}/link.csv"))
    fails(ds_dir, "samples[0].tests.T3.file", "outside the dataset folder")


# ------------------------------------------------------------------ CSV errors
def test_empty_csv(ds_dir):
    put(ds_dir, f"{S1}/T8.csv", "")
    fails(ds_dir, str(ds_dir / S1 / "T8.csv"), "empty file")


def test_no_header(ds_dir):
    put(ds_dir, f"{S1}/T8.csv", "# comment\n0,0,0,0\n0.1,1,1,1\n")
    e = fails(ds_dir, "T8.csv", "line 2", "no header", "time_s,voltage_V,current_A,force_N")
    put(ds_dir, f"{S1}/T8.csv", "# only a comment\n\n")
    fails(ds_dir, "T8.csv", "no header")
    assert e.line == 2


def test_misspelt_column_suggests(ds_dir):
    put(ds_dir, f"{S1}/T3.csv", "# c\ntime_s,voltage_V,current_A,displacment_mm\n0,0,0,0\n1,1,1,1\n")
    e = fails(ds_dir, f"{S1}/T3.csv", "line 2", "column 4", "'displacment_mm'", "did you mean 'displacement_mm'?")
    assert (e.line, e.column) == (2, 4)


def test_missing_column(ds_dir):
    put(ds_dir, f"{S1}/T7.csv", "gap_mm,current_A\n0,0.8\n")
    fails(ds_dir, "T7.csv", "line 1", "missing required column 'force_N'")


@pytest.mark.parametrize("rel, header, bad, unit", [
    (f"{S1}/T1.csv", "gap_mm,current_A,displacement_m", "displacement_m", "'mm'"),
    (f"{S1}/T3.csv", "time_ms,voltage_V,current_A,displacement_mm", "time_ms", "'s'"),
    (f"{S1}/T7.csv", "gap_mm,current_mA,force_N", "current_mA", "'A'"),
])
def test_wrong_unit_in_column_name(ds_dir, rel, header, bad, unit):
    n = len(header.split(","))
    put(ds_dir, rel, header + "\n" + ",".join(["1"] * n) + "\n" + ",".join(["2"] * n) + "\n")
    col = header.split(",").index(bad) + 1
    fails(ds_dir, rel, "line 1", f"column {col}", f"'{bad}'", "expects", unit)


def test_non_numeric_cell(ds_dir):
    put(ds_dir, f"{S1}/T3.csv", "time_s,voltage_V,current_A,displacement_mm\n0,0,0,0\n# x\n0.1,6.0V,1,1\n")
    e = fails(ds_dir, "T3.csv", "line 4", "column 2", "'voltage_V'", "non-numeric value '6.0V'")
    assert (e.line, e.column, e.column_name) == (4, 2, "voltage_V")


@pytest.mark.parametrize("cell", ["nan", "-inf", "1e999"])
def test_non_finite_cell(ds_dir, cell):
    put(ds_dir, f"{S2}/T1.csv", f"gap_mm,current_A,displacement_mm\n8,0.79,{cell}\n")
    fails(ds_dir, f"{S2}/T1.csv", "line 2", "column 3", "finite")


def test_wrong_number_of_cells(ds_dir):
    put(ds_dir, f"{S1}/T8.csv", "time_s,voltage_V,current_A,force_N\n0,0,0,0\n0.1,1,1\n")
    fails(ds_dir, "T8.csv", "line 3", "wrong number of cells: 3, the header has 4")
    put(ds_dir, f"{S1}/T8.csv", "time_s,voltage_V,current_A,force_N\n0,0,0,0\n0.1,1,1,0,5\n")
    fails(ds_dir, "T8.csv", "line 3", "decimal commas")


def test_time_not_strictly_increasing(ds_dir):
    put(ds_dir, f"{S1}/T6.csv", "time_s,voltage_V,current_A,displacement_mm\n0,0,0,0\n# c\n0.5,1,1,1\n0.5,1,1,1\n")
    e = fails(ds_dir, "T6.csv", "line 5", "column 1", "strictly increasing", "line 4")
    assert e.line == 5


def test_duplicate_gaps_name_both_lines(ds_dir):
    put(ds_dir, f"{S1}/T7.csv", "gap_mm,current_A,force_N\n0,0.8,0.31\n4,0.8,0.1\n4.0,0.8,0.12\n")
    fails(ds_dir, "T7.csv", "line 4", "duplicate gap 4 mm on lines 3 and 4")


@pytest.mark.parametrize("rel, text, fragment", [
    (f"{S1}/T3.csv", "time_s,voltage_V,current_A,displacement_mm\n0,0,0,0\n", "needs at least 2"),
    (f"{S1}/T1.csv", "gap_mm,current_A,displacement_mm\n# nothing measured\n", "needs at least 1"),
])
def test_too_few_rows(ds_dir, rel, text, fragment):
    put(ds_dir, rel, text)
    fails(ds_dir, rel, "too few data rows", fragment)


def test_problems_in_several_files_reported_together(ds_dir):
    put(ds_dir, f"{S1}/T8.csv", "")
    put(ds_dir, f"{S2}/T3.csv", "time_s,voltage_V,current_A,displacement_mm\n0,0,0,x\n1,1,1,1\n")
    e = fails(ds_dir, "2 problems", "T8.csv", "empty file", f"{S2}/T3.csv", "line 2")
    assert len(e.problems) == 2 and all(isinstance(p, DataFormatError) for p in e.problems)


# ------------------------------------------------------------------ validate mode, selection
def test_validate_required_tests(ds_dir):
    assert read_dataset(ds_dir, tests=("T1", "T3"))
    e = fails(ds_dir, f"sample '{S2}' lacks test(s) T6, T8", tests=("T3", "T6", "T8"))
    assert S1 not in str(e)
    with pytest.raises(ValueError, match="unknown test"):
        read_dataset(ds_dir, tests=("T3", "T10"))


def test_select_samples(ds_dir):
    put(ds_dir, f"{S2}/T3.csv", "broken")        # not selected -> not read
    ds = read_dataset(ds_dir, samples=[S1], tests=("T8",))
    assert [s.id for s in ds.samples] == [S1]
    fails(ds_dir, "unknown sample id(s) 'W99-D1'", S1, S2, samples=[S1, "W99-D1"])


def test_sample_lookup_unknown_id(ds_dir):
    ds = read_dataset(ds_dir)
    with pytest.raises(KeyError) as ei:
        ds.sample("nope")
    assert isinstance(ei.value, UnknownSampleError) and isinstance(ei.value, DataFormatError)
    assert "'nope'" in str(ei.value) and S1 in str(ei.value) and S2 in str(ei.value)


def test_written_files_get_the_umask_mode_not_mkstemp_0600(ds_dir, tmp_path):
    """Files are written atomically through mkstemp (mode 0600); they must end up readable by the group/others
    as any file a plain open() makes (0666 minus the umask), so a dataset can be shared."""
    import stat
    old = os.umask(0o022)
    try:
        out = tmp_path / "shared"
        write_dataset(read_dataset(ds_dir), out)
    finally:
        os.umask(old)
    modes = {p.relative_to(out).as_posix(): stat.S_IMODE(p.stat().st_mode) for p in out.rglob("*") if p.is_file()}
    assert modes and set(modes.values()) == {0o644}, modes


def test_empty_trailing_columns_as_excel_writes_them_are_ignored(ds_dir):
    # issue "Results you can trust under misuse", item 4: "a,b,c,," headers with empty cells under them
    put(ds_dir, f"{S1}/T8.csv", "# exported\ntime_s,voltage_V,current_A,force_N,,\n0,0,0,0,,\n0.1,1,1,0.5,,\n"
                                "0.2,1,1,0.25\n")
    t8 = read_dataset(ds_dir).sample(S1).tests["T8"]
    assert t8.force_N.tolist() == [0.0, 0.5, 0.25] and t8.time_s.tolist() == [0.0, 0.1, 0.2]
    # a value under a column without a name is not an empty column
    put(ds_dir, f"{S1}/T8.csv", "time_s,voltage_V,current_A,force_N,,\n0,0,0,0,,\n0.1,1,1,0.5,,7\n")
    fails(ds_dir, "T8.csv", "line 3", "column 6", "value '7' in column 6, which has no name in the header")
    # an empty name between named columns is still an error
    put(ds_dir, f"{S1}/T8.csv", "time_s,,voltage_V,current_A,force_N\n0,0,0,0,0\n0.1,1,1,1,0.5\n")
    fails(ds_dir, "T8.csv", "line 1", "column 2", "empty column name in the header")


def test_a_trailing_comma_is_not_called_a_decimal_comma(ds_dir):
    put(ds_dir, f"{S1}/T8.csv", "time_s,voltage_V,current_A,force_N\n0,0,0,0,\n0.1,1,1,0.5\n")
    e = fails(ds_dir, "T8.csv", "line 2", "wrong number of cells: 5, the header has 4",
              "the line ends with a comma")
    assert "decimal comma" not in str(e)
    put(ds_dir, f"{S1}/T8.csv", "time_s,voltage_V,current_A,force_N\n0,0,0,0\n0.1,1,1,x,y\n")
    e = fails(ds_dir, "T8.csv", "line 3", "wrong number of cells: 5, the header has 4")
    assert "decimal comma" not in str(e)


@pytest.mark.parametrize("rig, fragment", [
    ({"sweep_average_s": "0.3"}, "rig.sweep_average_s: sweep_average_s must be a number, got string"),
    ({"sweep_average_s": 0}, "rig.sweep_average_s: sweep_average_s must be > 0, got 0"),
    ({"sweep_average_s": 2.0, "sweep_hold_s": 1.5}, "rig.sweep_average_s: sweep_average_s must be <= "
                                                    "rig.sweep_hold_s (1.5 s), got 2"),
    ({"sweep_average_s": 0.0005, "sample_period_s": 0.001}, "rig.sweep_average_s: sweep_average_s must be at "
                                                            "least one sample period"),
    ({"sweep_hold_s": -1}, "rig.sweep_hold_s: sweep_hold_s must be > 0"),
    ({"sample_period_s": float("inf")}, "rig.sample_period_s"),
])
def test_rig_timing_keys_are_checked(ds_dir, rig, fragment):
    edit_manifest(ds_dir, lambda m: m["rig"].update(rig))
    fails(ds_dir, "manifest.json", fragment)


def test_rig_timing_keys_accepted(ds_dir):
    edit_manifest(ds_dir, lambda m: m["rig"].update(sweep_average_s=0.004, sweep_hold_s=2.0, sample_period_s=0.004))
    assert read_dataset(ds_dir).rig["sweep_average_s"] == 0.004
