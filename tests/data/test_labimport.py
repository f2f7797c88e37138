"""Lab-file import (harness.data.labimport): every supported dialect and container, unit conversion
against hand-computed values, round trips through read_dataset, and broken inputs.

Fixtures are written here: CSV/TSV text by hand, LVM by a small writer following NI's documented
LVM layout, TDMS by npTDMS's TdmsWriter, MAT v5 by scipy.io.savemat.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from harness.data.dataset import read_dataset
from harness.cli import main as cli_main
from harness.data.labimport import LabImportError, import_lab_files, read_lvm, read_text_table, split_unit, unit_factor

# hand-written lab values and the same in the format's units (s, V, A, mm, N)
T_MS = [0.0, 1.0, 2.0, 3.0, 4.0]
T_S = [0.0, 0.001, 0.002, 0.003, 0.004]
V_V = [0.0, 11.9, 11.9, 11.9, 11.9]
I_MA = [0.0, 250.0, 500.0, 701.5, 793.0]
I_A = [0.0, 0.25, 0.5, 0.7015, 0.793]
X_UM = [0.0, 12.0, 340.0, 1200.5, 1560.3]
X_MM = [0.0, 0.012, 0.34, 1.2005, 1.5603]
F_MN = [0.0, 120.5, 240.0, 280.25, 300.0]
F_N = [0.0, 0.1205, 0.24, 0.28025, 0.3]
GAP_CM = [2.5, 2.0, 1.5, 1.0, 0.5]
GAP_MM = [25.0, 20.0, 15.0, 10.0, 5.0]

SAMPLE = {"id": "W20-D45", "wt_pct": 20, "diameter_mm": 45, "thickness_mm": 1.5}
RIG = {"coil_radius_mm": 15.0, "field_per_amp_T_per_A": 0.29}


def mapping(tests: dict, base: Path, **extra) -> dict:
    return {"base_dir": str(base), "rig": dict(RIG), "samples": [{**SAMPLE, "tests": tests}], **extra}


def t5(file: str, columns: dict, **kw) -> dict:
    return {"T5": {"file": file, "field_T": 0.23, "gap_mm": 5.0, "columns": columns, **kw}}


def close(a, b):
    np.testing.assert_allclose(np.asarray(a, float), np.asarray(b, float), rtol=1e-12, atol=1e-15)


def fmt(x: float, dec: str = ".") -> str:
    return repr(float(x)).replace(".", dec)


def snapshot(folder: Path) -> dict:
    return {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(folder.rglob("*")) if p.is_file()}


# ================================================================ CSV dialects
def test_comma_csv_units_in_brackets_and_parentheses(tmp_path):
    raw = tmp_path / "raw"
    raw.mkdir()
    rows = [",".join(fmt(v) for v in r) for r in zip(T_MS, V_V, I_MA, X_UM)]
    (raw / "t5.csv").write_text("Time (ms),Voltage [V],Current (mA),Displacement [µm]\n" + "\n".join(rows) + "\n",
                                encoding="utf-8")
    before = snapshot(raw)
    out = import_lab_files(mapping(t5("t5.csv", {"time": "Time", "voltage": "Voltage [V]", "current": "Current",
                                                 "displacement": "Displacement [µm]"}), raw), tmp_path / "ds")
    assert snapshot(raw) == before                      # inputs untouched: bytes and mtimes
    ts = read_dataset(out).sample("W20-D45").test("T5")
    close(ts.time_s, T_S)
    close(ts.voltage_V, V_V)
    close(ts.current_A, I_A)
    close(ts.displacement_mm, X_MM)
    assert ts.gap_mm == 5.0 and ts.field_T == 0.23


def test_semicolon_decimal_comma_bom_crlf_preamble_trailing_empty_columns(tmp_path):
    """An Excel (German locale) export: BOM, CRLF, preamble, decimal comma, empty trailing columns."""
    lines = ["Messung 12;Probe W20-D45;;;;", "Datum;23.11.2026;;;;", ";;;;;",
             "Zeit [ms];Spannung [V];Strom (mA);Weg [µm];;"]
    lines += [";".join(fmt(v, ",") for v in r) + ";;" for r in zip(T_MS, V_V, I_MA, X_UM)]
    f = tmp_path / "t5.csv"
    f.write_bytes(b"\xef\xbb\xbf" + "\r\n".join(lines).encode("utf-8") + b"\r\n")
    tab = read_text_table(f)
    assert tab.notes["delimiter"] == ";" and tab.notes["decimal"] == ","
    assert tab.notes["header_line"] == 4
    assert [c.unit for c in tab.channels] == ["ms", "V", "mA", "µm"]
    out = import_lab_files(mapping(t5("t5.csv", {"time": "Zeit", "voltage": "Spannung", "current": "Strom",
                                                 "displacement": "Weg"}), tmp_path), tmp_path / "ds")
    ts = read_dataset(out).sample("W20-D45").test("T5")
    close(ts.time_s, T_S)
    close(ts.current_A, I_A)
    close(ts.displacement_mm, X_MM)


def test_tab_separated_with_comments_and_quoted_header(tmp_path):
    lines = ["# exported by the rig PC", '"time_ms"\t"U (V)"\t"I [A]"\t"F [mN]"', "% a comment inside"]
    lines += ["\t".join(fmt(v) for v in r) for r in zip(T_MS, V_V, I_A, F_MN)]
    (tmp_path / "t8.tsv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    m = mapping({"T8": {"file": "t8.tsv", "field_T": 0.23, "gap_mm": 2.0,
                        "columns": {"time": "time_ms", "voltage": "U", "current": "I", "force": "F"}}}, tmp_path)
    ts = read_dataset(import_lab_files(m, tmp_path / "ds")).sample("W20-D45").test("T8")
    close(ts.time_s, T_S)
    close(ts.force_N, F_N)
    close(ts.current_A, I_A)


def test_whitespace_separated_gap_sweep_with_units_row(tmp_path):
    """Fixed-width text: names with spaces separated by two or more blanks, a units row under them."""
    lines = ["Gap width    Coil current    Deflection", "cm           mA              µm"]
    lines += [f"{g:<12} {i:<15} {x}" for g, i, x in zip(GAP_CM, I_MA, X_UM)]
    (tmp_path / "t1.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")
    tab = read_text_table(tmp_path / "t1.txt")
    assert tab.notes["delimiter"] == "whitespace"
    assert tab.names() == ["Gap width", "Coil current", "Deflection"]
    m = mapping({"T1": {"file": "t1.txt", "field_T": 0.23,
                        "columns": {"gap": "Gap width", "current": "Coil current", "displacement": "Deflection"}}},
                tmp_path)
    sw = read_dataset(import_lab_files(m, tmp_path / "ds")).sample("W20-D45").test("T1")
    close(sw.gap_mm, GAP_MM)
    close(sw.current_A, I_A)
    close(sw.displacement_mm, X_MM)


def test_whitespace_decimal_comma_and_quoted_decimal_comma_with_comma_separator(tmp_path):
    (tmp_path / "a.txt").write_text("t_s  I_A\n0,5  1,25\n1,5  2,75\n", encoding="utf-8")
    tab = read_text_table(tmp_path / "a.txt")
    close(tab.find("t_s").values, [0.5, 1.5])
    close(tab.find("I_A").values, [1.25, 2.75])
    (tmp_path / "b.csv").write_text('"t [s]","I [A]"\n"0,5","1,25"\n"1,5","2,75"\n', encoding="utf-8")
    tab = read_text_table(tmp_path / "b.csv")
    assert tab.notes["delimiter"] == "," and tab.notes["decimal"] == ","
    close(tab.find("I").values, [1.25, 2.75])


def test_no_header_columns_by_number_with_units_from_mapping(tmp_path):
    (tmp_path / "t5.dat").write_text("\n".join(" ".join(fmt(v) for v in r) for r in zip(T_MS, V_V, I_MA, X_UM)))
    m = mapping(t5("t5.dat", {"time": 1, "voltage": 2, "current": 3, "displacement": 4},
                   units={"time": "ms", "voltage": "V", "current": "mA", "displacement": "um"}), tmp_path)
    ts = read_dataset(import_lab_files(m, tmp_path / "ds")).sample("W20-D45").test("T5")
    close(ts.time_s, T_S)
    close(ts.displacement_mm, X_MM)


def test_negate_and_mapping_overrides_dialect(tmp_path):
    # '1,000' everywhere: a thousands separator or a decimal comma? The mapping says.
    (tmp_path / "s.txt").write_text("Gap [mm]\tI [A]\tx [mm]\n1,000\t0,500\t-1,250\n2,000\t0,500\t-0,750\n")
    m = mapping({"T1": {"file": "s.txt", "field_T": 0.23, "columns": {"gap": "Gap", "current": "I",
                                                                         "displacement": "x"},
                        "negate": ["displacement"], "csv": {"decimal": ",", "delimiter": "tab"}}}, tmp_path)
    sw = read_dataset(import_lab_files(m, tmp_path / "ds")).sample("W20-D45").test("T1")
    close(sw.gap_mm, [1.0, 2.0])
    close(sw.displacement_mm, [1.25, 0.75])


# ================================================================ units
def test_units_parsed_and_converted_by_hand_values():
    assert split_unit("Time [s]") == ("Time", "s")
    assert split_unit("Current (mA)") == ("Current", "mA")
    assert split_unit("Gap (mm)") == ("Gap", "mm")
    assert split_unit("displacement_um") == ("displacement", "um")
    assert split_unit("Voltage") == ("Voltage", None)
    assert unit_factor("ms", "time") == 1e-3
    assert unit_factor("µm", "displacement") == 1e-3
    assert unit_factor("\u03bcm", "displacement") == 1e-3      # Greek mu
    assert unit_factor("m", "gap") == 1e3
    assert unit_factor("mN", "force") == 1e-3
    assert unit_factor("mA", "current") == 1e-3
    with pytest.raises(LabImportError, match="unknown unit 'furlong'"):
        unit_factor("furlong", "gap")
    with pytest.raises(LabImportError, match="unit 'mA' is a unit of current, but the displacement column needs"):
        unit_factor("mA", "displacement")


# ================================================================ LVM
def write_lvm(path: Path, channels: dict, dt_s: float, *, x_columns="One", sep="\t", decimal=".",
              x0_s: float = 0.0) -> None:
    """A minimal LVM writer following NI's documented layout (file header, one segment)."""
    names = list(channels)
    n = len(next(iter(channels.values()))[0])
    num = (lambda v: f"{v:.6f}".replace(".", decimal))
    sep_name = {"\t": "Tab", ",": "Comma"}[sep]
    L = ["LabVIEW Measurement", f"Writer_Version{sep}2", f"Reader_Version{sep}2", f"Separator{sep}{sep_name}",
         f"Decimal_Separator{sep}{decimal}", f"Multi_Headings{sep}No", f"X_Columns{sep}{x_columns}",
         f"Time_Pref{sep}Relative", f"Operator{sep}lab", f"Date{sep}2026/11/23", f"Time{sep}09:00:00",
         "***End_of_Header***", "",
         f"Channels{sep}{len(names)}", "Samples" + sep + sep.join(str(n) for _ in names),
         "Y_Unit_Label" + sep + sep.join(channels[k][1] for k in names),
         "X_Dimension" + sep + sep.join("Time" for _ in names),
         "X0" + sep + sep.join(num(x0_s) for _ in names),
         "Delta_X" + sep + sep.join(num(dt_s) for _ in names), "***End_of_Header***"]
    L.append(sep.join((["X_Value"] if x_columns == "One" else []) + names + ["Comment"]))
    for i in range(n):
        row = ([num(x0_s + i * dt_s)] if x_columns == "One" else []) + [num(channels[k][0][i]) for k in names]
        L.append(sep.join(row))
    path.write_text("\r\n".join(L) + "\r\n", encoding="utf-8")


def test_lvm_one_x_column_decimal_comma(tmp_path):
    write_lvm(tmp_path / "t5.lvm", {"Voltage": (V_V, "V"), "Current": (I_MA, "mA"), "Laser": (X_UM, "um")},
              1e-3, decimal=",")
    tab = read_lvm(tmp_path / "t5.lvm")
    assert tab.names() == ["X_Value", "Voltage", "Current", "Laser"]
    m = mapping(t5("t5.lvm", {"voltage": "Voltage", "current": "Current", "displacement": "Laser"}), tmp_path)
    ts = read_dataset(import_lab_files(m, tmp_path / "ds")).sample("W20-D45").test("T5")
    close(ts.time_s, T_S)
    close(ts.current_A, I_A)
    close(ts.displacement_mm, X_MM)


def test_lvm_no_x_column_time_from_x0_delta_x(tmp_path):
    write_lvm(tmp_path / "t8.lvm", {"U": (V_V, "V"), "I": (I_A, "A"), "F": (F_MN, "mN")}, 0.5e-3,
              x_columns="No", sep=",", x0_s=12.0)
    m = mapping({"T8": {"file": "t8.lvm", "field_T": 0.23, "gap_mm": 2.0,
                        "columns": {"voltage": "U", "current": "I", "force": "F"}}}, tmp_path)
    ts = read_dataset(import_lab_files(m, tmp_path / "ds")).sample("W20-D45").test("T8")
    close(ts.time_s, [12.0 + 0.5e-3 * k for k in range(5)])
    close(ts.force_N, F_N)


def test_lvm_bad_cell_names_line_and_column(tmp_path):
    f = tmp_path / "t.lvm"
    write_lvm(f, {"Voltage": (V_V, "V"), "Current": (I_MA, "mA")}, 1e-3)
    lines = f.read_bytes().decode("utf-8").split("\r\n")
    k = lines.index(next(ln for ln in lines if ln.startswith("X_Value"))) + 3
    lines[k] = lines[k].replace(lines[k].split("\t")[2], "oops")
    f.write_bytes("\r\n".join(lines).encode("utf-8"))
    with pytest.raises(LabImportError) as e:
        read_lvm(f)
    assert e.value.line == k + 1 and e.value.column == 3 and e.value.column_name == "Current"


# ================================================================ TDMS
def test_tdms_waveform_channels_with_unit_strings(tmp_path):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter
    f = tmp_path / "t5.tdms"
    wf = {"wf_increment": 1e-3, "wf_start_offset": 0.0}
    with TdmsWriter(str(f)) as w:
        w.write_segment([RootObject({"operator": "lab"}), GroupObject("Step"),
                         ChannelObject("Step", "Voltage", np.array(V_V), {"unit_string": "V", **wf}),
                         ChannelObject("Step", "Current", np.array(I_MA), {"unit_string": "mA", **wf}),
                         ChannelObject("Step", "Laser", np.array(X_UM), {"unit_string": "µm", **wf})])
    before = snapshot(tmp_path)
    m = mapping(t5("t5.tdms", {"voltage": "Step/Voltage", "current": "Current", "displacement": "Step/Laser"}),
                tmp_path)
    ts = read_dataset(import_lab_files(m, tmp_path / "ds")).sample("W20-D45").test("T5")
    assert {p: v for p, v in snapshot(tmp_path).items() if "ds" not in p.parts} == before
    close(ts.time_s, T_S)
    close(ts.current_A, I_A)
    close(ts.displacement_mm, X_MM)
    bad = mapping(t5("t5.tdms", {"voltage": "Step/Voltage", "current": "Step/Curent", "displacement": "Step/Laser"}),
                  tmp_path)
    with pytest.raises(LabImportError, match=r"no column or channel 'Step/Curent'.*did you mean 'Step/Current'"):
        import_lab_files(bad, tmp_path / "ds2")


# ================================================================ MAT
def test_mat_v5_vectors_and_matrix_columns(tmp_path):
    from scipy.io import savemat
    savemat(tmp_path / "t1.mat", {"gap_cm": np.array(GAP_CM), "data": np.column_stack([I_MA, X_UM])},
            format="5")
    m = mapping({"T1": {"file": "t1.mat", "field_T": 0.23,
                        "columns": {"gap": "gap_cm", "current": "data:1", "displacement": "data:2"},
                        "units": {"current": "mA", "displacement": "µm"}}}, tmp_path)
    sw = read_dataset(import_lab_files(m, tmp_path / "ds")).sample("W20-D45").test("T1")
    close(sw.gap_mm, GAP_MM)
    close(sw.current_A, I_A)
    close(sw.displacement_mm, X_MM)


def test_mat_v73_refused_clearly(tmp_path):
    f = tmp_path / "big.mat"
    f.write_bytes(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 23 2026 HDF5 schema 1.00 ."
                  .ljust(512, b" ") + b"\x89HDF\r\n\x1a\n" + b"\0" * 64)
    m = mapping({"T1": {"file": "big.mat", "field_T": 0.23,
                        "columns": {"gap": "g", "current": "i", "displacement": "x"}}}, tmp_path)
    with pytest.raises(LabImportError, match=r"v7\.3 \(HDF5\) files are not supported.*h5py"):
        import_lab_files(m, tmp_path / "ds")


# ================================================================ mapping file, CLI, output folder
def test_mapping_file_relative_paths_and_cli(tmp_path, capsys):
    (tmp_path / "raw").mkdir()
    (tmp_path / "raw" / "t7.csv").write_text("Gap (mm),I (A),F (N)\n" + "\n".join(
        f"{g},{i},{f}" for g, i, f in zip(GAP_MM, I_A, F_N)) + "\n")
    mfile = tmp_path / "map.json"
    mfile.write_text(json.dumps({"format": "mpc-actuator-labimport/1", "rig": {**RIG, "sweep_average_s": 0.3},
                                 "samples": [{**SAMPLE, "tests": {"T7": {"file": "raw/t7.csv", "field_T": 0.23,
                                              "columns": {"gap": "Gap", "current": "I", "force": "F"}}}}]}))
    cli_main(["import", str(mfile), "--out", str(tmp_path / "ds")])
    assert "wrote dataset" in capsys.readouterr().out
    ds = read_dataset(tmp_path / "ds")
    assert ds.synthetic is False and ds.rig["sweep_average_s"] == 0.3
    close(ds.sample("W20-D45").test("T7").force_N, F_N)
    with pytest.raises(SystemExit) as exc:                        # not empty now
        cli_main(["import", str(mfile), "--out", str(tmp_path / "ds")])
    assert str(exc.value).startswith("error: ") and "not empty" in str(exc.value)


def test_output_folder_not_empty_and_input_inside_output_refused(tmp_path):
    (tmp_path / "t7.csv").write_text("Gap (mm),I (A),F (N)\n1,0.5,0.1\n")
    m = mapping({"T7": {"file": "t7.csv", "field_T": 0.23, "columns": {"gap": "Gap", "current": "I",
                                                                         "force": "F"}}}, tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(LabImportError, match="not empty"):
        import_lab_files(m, out)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    with pytest.raises(LabImportError, match="holds this input file"):
        import_lab_files(m, tmp_path, overwrite=True)


# ================================================================ broken inputs
def _err(tmp_path, text: str, columns: dict, name="t5.csv", **kw) -> LabImportError:
    (tmp_path / name).write_text(text, encoding="utf-8")
    with pytest.raises(LabImportError) as e:
        import_lab_files(mapping(t5(name, columns, **kw), tmp_path), tmp_path / "ds")
    assert not (tmp_path / "ds").exists()
    return e.value


COLS = {"time": "t", "voltage": "V", "current": "I", "displacement": "x"}


def test_missing_column(tmp_path):
    e = _err(tmp_path, "t [s],V [V],I [A]\n0,0,0\n0.001,1,0.1\n", COLS)
    assert "no column or channel 'x'" in str(e) and "t5.csv" in str(e)


def test_unknown_and_wrong_units(tmp_path):
    e = _err(tmp_path, "t [s],V [V],I [A],x [furlong]\n0,0,0,0\n0.001,1,0.1,2\n", COLS)
    assert "unknown unit 'furlong'" in str(e) and e.column == 4 and e.column_name == "x [furlong]"
    e = _err(tmp_path, "t [s],V [V],I [A],x [mA]\n0,0,0,0\n0.001,1,0.1,2\n", COLS, name="b.csv")
    assert "unit of current" in str(e) and "length" in str(e)
    e = _err(tmp_path, "t [s],V,I [A],x [mm]\n0,0,0,0\n0.001,1,0.1,2\n", COLS, name="c.csv")
    assert "no unit for the voltage column" in str(e)


def test_non_numeric_cell_names_line_and_column(tmp_path):
    text = "# comment\nt [s];V [V];I [A];x [mm]\n0;0;0;0\n0.001;1;0.1;0.2\n0.002;1;n/a;0.3\n"
    e = _err(tmp_path, text, COLS)
    assert (e.line, e.column, e.column_name) == (5, 3, "I [A]")
    assert "line 5" in str(e) and "column 3" in str(e) and "'n/a' is not a number" in str(e)


def test_ambiguous_decimal_comma(tmp_path):
    e = _err(tmp_path, "t [s],V [V],I [A],x [mm]\n0,0,0,0,0,0,0,0\n0,1,1,0,0,1,0,2\n", COLS)
    assert "ambiguous decimal comma" in str(e) and e.line == 2
    e = _err(tmp_path, "t [s];V [V];I [A];x [mm]\n0;0;0;0\n1,000;12,000;1,500;2,000\n", COLS, name="k.csv")
    assert "ambiguous decimal comma" in str(e) and "thousands" in str(e)


def test_time_not_increasing_names_line(tmp_path):
    e = _err(tmp_path, "t [s],V [V],I [A],x [mm]\n0,0,0,0\n0.002,1,0.1,0.2\n0.001,1,0.1,0.3\n", COLS)
    assert "not strictly increasing" in str(e) and e.line == 4
    assert "(0.002 s then 0.001 s, row 3)" in str(e) and "np.float64" not in str(e)     # plain numbers


def test_mapping_errors_name_the_key(tmp_path):
    m = mapping(t5("t5.csv", COLS), tmp_path)
    m["samples"][0]["tests"]["T5"]["colums"] = m["samples"][0]["tests"]["T5"].pop("columns")
    with pytest.raises(LabImportError, match=r"samples\[0\]\.tests\.T5\.colums: unknown key.*did you mean 'columns'"):
        import_lab_files(m, tmp_path / "ds")
    m = mapping(t5("t5.csv", COLS), tmp_path)
    del m["samples"][0]["tests"]["T5"]["gap_mm"]
    with pytest.raises(LabImportError, match=r"samples\[0\]\.tests\.T5\.gap_mm: missing key"):
        import_lab_files(m, tmp_path / "ds")
    m = mapping(t5("t5.csv", {**COLS, "speed": "v"}), tmp_path)
    with pytest.raises(LabImportError, match=r"columns\.speed: unknown key"):
        import_lab_files(m, tmp_path / "ds")
    bad = tmp_path / "bad.json"
    bad.write_text('{"samples": [\n  {"id": "a",}\n]}')
    with pytest.raises(LabImportError) as e:
        import_lab_files(bad, tmp_path / "ds")
    assert e.value.line == 2 and "bad.json" in str(e.value)


def test_lab_import_error_is_a_value_error():
    assert issubclass(LabImportError, ValueError)
    e = LabImportError("cell 'x' is not a number", file="a.csv", line=3, column=2, column_name="I [A]")
    assert str(e) == "a.csv, line 3, column 2 ('I [A]'): cell 'x' is not a number"


def test_inputs_never_modified_even_when_the_import_fails(tmp_path):
    (tmp_path / "t5.csv").write_text("t [s],V [V],I [A],x [mm]\n0,0,0,0\n0.001,1,abc,0.2\n")
    os.utime(tmp_path / "t5.csv", ns=(1_000_000_000, 1_000_000_000))
    before = snapshot(tmp_path)
    with pytest.raises(LabImportError):
        import_lab_files(mapping(t5("t5.csv", COLS), tmp_path), tmp_path / "ds")
    assert snapshot(tmp_path) == before


def test_docstring_examples_run():
    import doctest

    import harness.data.labimport.units as units
    for mod in (units,):
        res = doctest.testmod(mod)
        assert res.attempted > 0 and res.failed == 0, mod.__name__
