"""Option values are checked where they are parsed (harness.options): one line ``error: --option ...`` naming the
allowed range and the value, exit code 1, before any work; argparse's own usage errors keep exit code 2."""
from __future__ import annotations

import json

import pytest

from harness import cli
from harness.options import OptionValueError, number


def _fails(argv, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    assert capsys.readouterr().err == ""          # no usage text, no traceback
    return e.value.code


@pytest.mark.parametrize("argv, msg", [
    (["uncertainty", "DS", "--params", "p.json", "--draws", "4"], "--draws must be a whole number >= 8, got 4"),
    (["uncertainty", "DS", "--params", "p.json", "--bootstrap", "10"],
     "--bootstrap must be a whole number >= 100, got 10"),
    (["uncertainty", "DS", "--params", "p.json", "--draws", "8.5"], "--draws must be a whole number >= 8, got '8.5'"),
    (["generate", "--workers", "two"], "--workers must be a whole number >= 1 (1 = run in this process), got 'two'"),
    (["generate", "--seed", "-1"], "--seed must be a whole number >= 0, got -1"),
    (["identify", "DS", "--pop-size", "2"], "--pop-size must be a whole number >= 4, got 2"),
    (["identify", "DS", "--generations", "0"], "--generations must be a whole number >= 1, got 0"),
    (["identify", "DS", "--weights", "1", "-1", "1", "1"], "--weights must be a finite number >= 0, got -1"),
    (["identify", "DS", "--weights", "0", "0", "0", "0"], "--weights must not all be zero, got 0 0 0 0"),
    (["design", "--uncertainty", "u.json", "--stroke-mm", "inf"], "--stroke-mm must be a finite number > 0, got inf"),
    (["design", "--uncertainty", "u.json", "--stroke-mm", "1", "--points", "1"],
     "--points must be a whole number >= 2, got 1"),
    (["design", "--uncertainty", "u.json", "--stroke-mm", "1", "--voltage-V", "0", "5"],
     "--voltage-V must be a finite number > 0, got 0"),
    (["design", "--uncertainty", "u.json", "--stroke-mm", "1", "--step-s", "0"],
     "--step-s must be a finite number > 0, got 0"),
    (["design", "--uncertainty", "u.json", "--stroke-mm", "1", "--draws", "0"],
     "--draws must be a whole number >= 1, got 0"),
    (["build", "--params", "p.json", "--gap-mm", "-1"], "--gap-mm must be a finite number >= 0, got -1"),
])
def test_a_bad_option_value_is_one_line_naming_option_range_and_value(tmp_path, capsys, argv, msg):
    if argv[0] != "check":
        argv = argv + ["--out", str(tmp_path / "out")]
    assert _fails(argv, capsys) == f"error: {msg}"
    assert not (tmp_path / "out").exists()


def test_argparse_usage_errors_keep_exit_code_2(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["generate", "--no-such-option"])
    assert e.value.code == 2 and "usage:" in capsys.readouterr().err


def test_number_ranges():
    assert number("--x", 0, 1, lo_open=True)("1") == 1.0
    with pytest.raises(OptionValueError, match=r"^--x must be a finite number in \(0, 1\], got 0$"):
        number("--x", 0, 1, lo_open=True)("0")
    with pytest.raises(OptionValueError, match=r"^--n must be a whole number < 3, got 3$"):
        number("--n", hi=3, hi_open=True, integer=True)("3")
    assert number("--n", integer=True)("-7") == -7


def test_a_file_that_is_not_an_fmu_is_named(tmp_path, capsys):
    fake = tmp_path / "fake.fmu"
    fake.write_text("not a zip")
    ref = tmp_path / "refs"
    ref.mkdir()
    assert _fails(["crosscheck", "check", str(ref), "--fmu", str(fake)], capsys) == (
        f"error: FMU {fake} is not an FMU (not a zip archive); build one with `python build_fmu.py`")
    import zipfile
    with zipfile.ZipFile(fake, "w") as z:
        z.writestr("readme.txt", "x")
    assert _fails(["crosscheck", "check", str(ref), "--fmu", str(fake)], capsys) == (
        f"error: FMU {fake} is not an FMU (the archive holds no modelDescription.xml); build one with "
        f"`python build_fmu.py`")


def _dataset(tmp_path, csv_text):
    ds = tmp_path / "ds"
    (ds / "S").mkdir(parents=True)
    (ds / "S" / "T3.csv").write_text(csv_text)
    (ds / "manifest.json").write_text(json.dumps({
        "format": "mpc-actuator-data/1", "synthetic": True, "rig": {"coil_radius_mm": 15.0},
        "samples": [{"id": "W20-D45", "wt_pct": 20, "diameter_mm": 45, "thickness_mm": 1.5,
                     "tests": {"T3": {"file": "S/T3.csv", "field_T": 0.11, "gap_mm": 9.0}}}]}))
    return ds


@pytest.mark.parametrize("csv_text, msg", [
    ('time_s,voltage_V,current_A,displacement_mm\n"0","0","0","0"\n"0,01","6","0,2","0,3"\n',
     r"T3.csv, line 3, column 1 \('time_s'\): non-numeric value '0,01' \(decimal commas are not allowed; use '.'\)$"),
    ("time_s,voltage_V,current_A,displacement_mm\n0,0,0,0\n0,01,6,0,2,0,3\n",
     r"T3.csv, line 3: wrong number of cells: 7, the header has 4 \(decimal commas are not allowed; use '.'\)$"),
    ("time_s;voltage_V;current_A;displacement_mm\n0;0;0;0\n0,01;6;0,2;0,3\n",
     r"T3.csv, line 1: missing required column 'time_s' .*the header seems to be separated by semicolons"),
])
def test_check_of_decimal_commas_is_one_line(tmp_path, capsys, csv_text, msg):
    import re
    code = _fails(["check", str(_dataset(tmp_path, csv_text))], capsys)
    assert "\n" not in code and code.startswith("error: ") and re.search(msg, code), code


def _spreadsheet_export(src, dst, dialect):
    """A copy of dataset ``src`` whose every CSV is written as a spreadsheet in a decimal-comma locale would write
    it: ``plain`` (',' between cells and as decimal mark), ``quoted`` (each cell in quotes) or ``semicolons``."""
    import shutil
    shutil.copytree(src, dst)
    for f in sorted(dst.rglob("*.csv")):
        out = []
        for ln in f.read_text().splitlines():
            if ln.startswith("#") or not ln:
                out.append(ln)
            elif ln[0].isdigit() or ln[0] == "-":
                cells = [c.replace(".", ",") for c in ln.split(",")]
                out.append(";".join(cells) if dialect == "semicolons" else
                           ",".join(f'"{c}"' if dialect == "quoted" else c for c in cells))
            else:
                out.append(ln.replace(",", ";") if dialect == "semicolons" else ln)
        f.write_text("\n".join(out) + "\n")
    return dst


@pytest.mark.parametrize("dialect, first", [
    ("quoted", r"W10-D30/T1\.csv, line 2, column 2 \('current_A'\): non-numeric value '0,\d+' \(decimal commas"),
    ("plain", r"W10-D30/T1\.csv, line 2: wrong number of cells: 5, the header has 3 \(decimal commas"),
    ("semicolons", r"W10-D30/T1\.csv, line 1: missing required column 'gap_mm' .*separated by semicolons"),
])
def test_check_of_a_dataset_exported_with_decimal_commas_is_one_line(tmp_path, capsys, dialect, first):
    """Issue 24.5: every file of a sample (here of three samples) written with decimal commas printed one line per
    file; now one line: the first problem in full (file, line, column, what), how many more files, the lab import."""
    import re
    from pathlib import Path
    fixture = Path(__file__).resolve().parents[1] / "fixtures" / "clean-500hz-3-samples"
    ds = _spreadsheet_export(fixture, tmp_path / "ds", dialect)
    code = _fails(["check", str(ds)], capsys)
    assert isinstance(code, str) and "\n" not in code and code.startswith(f"error: {ds}/"), code
    assert re.search(first, code), code
    assert "the same in 23 more files (T2.csv, T3.csv, T4.csv, ...)" in code and "`mpc-actuator import`" in code
    # another problem besides them stays a line of its own
    (ds / "W20-D45" / "T5.csv").unlink()
    code = _fails(["check", str(ds)], capsys)
    lines = code.splitlines()
    assert lines[0] == f"error: 2 problems in dataset {ds}:" and len(lines) == 3, code
    assert "the same in 22 more files" in code and "W20-D45/T5.csv" in code, code
