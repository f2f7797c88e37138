"""Tests of harness.report.tables (paper Tables 3-5)."""
import csv
import math

import numpy as np
import pytest

from harness.report import tables


def _rec(sample, wt, d, test, **metrics):
    return {"sample": sample, "wt_pct": wt, "diameter_mm": d, "test": test, **metrics}


@pytest.fixture
def records():
    """Hand-made records: D45 with 10/20/30 wt% (+ unseen 15 and 25), D30 with one sample."""
    r = []
    for wt, (rm3, st3, rm5, st5) in {10: (0.01, 0.1, 0.05, 0.02),
                                     20: (0.02, 0.3, 0.07, 0.04),
                                     30: (0.06, 0.5, 0.12, 0.09)}.items():
        s = f"W{wt}-D45"
        r += [_rec(s, wt, 45, "T3", rmse_mm=rm3, ste_s=st3),
              _rec(s, wt, 45, "T5", rmse_mm=rm5, ste_s=st5),
              _rec(s, wt, 45, "T6", amplitude_ratio=0.9 + wt / 1000, phase_shift_rad=-0.2 - wt / 1000),
              _rec(s, wt, 45, "T7", rmse_N=wt / 1000)]
    r.append(_rec("W10-D30", 10, 30, "T3", rmse_mm=0.0141, ste_s=float("nan")))
    r.append(_rec("W10-D30", 10, 30, "T5", rmse_mm=0.0275, ste_s=0.166))
    r.append(_rec("W20-D30", 20, 30, "T5", rmse_mm=0.0375, ste_s=0.266))
    r.append(_rec("W15-D45", 15, 45, "T2", rmse_mm=0.0233, ste_s=0.366))
    r.append(_rec("W15-D45", 15, 45, "T7", rmse_N=0.0070))
    r.append(_rec("W25-D45", 25, 45, "T6", amplitude_ratio=0.9303, phase_shift_rad=-0.039))
    return r


def _row(md, first_cell):
    for line in md.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells and cells[0] == first_cell:
            return cells
    raise AssertionError(f"no row {first_cell!r} in\n{md}")


def _sd(*v):
    m = sum(v) / len(v)
    return math.sqrt(sum((x - m) ** 2 for x in v) / (len(v) - 1))


# --------------------------------------------------------------------------- tables
def test_table3_mean_and_sample_std(records):
    md = tables.table3_markdown(records)
    header = _row(md, "Diameter (mm)")
    assert header == ["Diameter (mm)", "T3 RMSE (mm)", "T3 STE (s)", "T5 RMSE (mm)", "T5 STE (s)"]
    row = _row(md, "45")
    # 10/20/30 wt% only: the unseen 15 and 25 wt% samples are not part of Table 3
    assert row[1] == f"0.0300 ({_sd(0.01, 0.02, 0.06):.4f})" == "0.0300 (0.0265)"
    assert row[2] == "0.3000 (0.2000)"
    assert row[3] == f"0.0800 ({_sd(0.05, 0.07, 0.12):.4f})"
    assert row[4] == f"0.0500 ({_sd(0.02, 0.04, 0.09):.4f})"


def test_single_value_missing_and_nonfinite_cells(records):
    md = tables.table3_markdown(records)
    row = _row(md, "30")
    assert row[1] == "0.0141 (n/a)"          # one sample: value and (n/a)
    assert row[2] == "NaN†"                  # only value non-finite
    assert row[3] == f"0.0325 ({_sd(0.0275, 0.0375):.4f})"
    assert "never settled" in md
    md4 = tables.table4_markdown(records)
    row4 = _row(md4, "30")
    assert row4[1:] == ["–"] * 8               # no validation test for D30
    row45 = _row(md4, "45")
    assert row45[1] == "–"                     # T1 missing
    assert row45[6] == "0.9200 (0.0100)"       # T6 amplitude ratio
    assert row45[7] == "-0.2200 (0.0100)"      # T6 phase shift
    assert row45[8] == "0.0200 (0.0100)"       # T7 in N
    assert "T7 RMSE (N)" in _row(md4, "Diameter (mm)")


def test_captions_name_the_samples(records):
    assert tables.table3_markdown(records).startswith(
        "Table 3. Multi-objective optimization (identification) results, samples 10, 20, 30 wt%.\n\n|")
    assert tables.table4_markdown(records, wt_pct=None).startswith(
        "Table 4. Model validation results, samples all (T7 is a blocked-force RMSE, in N).\n\n|")
    assert tables.table4_markdown(records, wt_pct=(15, 25)).startswith(
        "Table 4. Model validation results, samples 15, 25 wt% (T7 is a blocked-force RMSE, in N).\n")


def test_partially_nonfinite_cell_is_flagged():
    recs = [_rec("a", 10, 45, "T3", ste_s=0.1), _rec("b", 20, 45, "T3", ste_s=float("nan")),
            _rec("c", 30, 45, "T3", ste_s=0.3)]
    row = _row(tables.table3_markdown(recs), "45")
    assert row[2] == f"0.2000 ({_sd(0.1, 0.3):.4f})†"


def test_table5_rows_per_sample(records):
    md = tables.table5_markdown(records, ["W15-D45", "W25-D45"])
    header = _row(md, "Sample")
    row15, row25 = _row(md, "W15-D45"), _row(md, "W25-D45")
    assert row15[1:3] == ["45", "15"] and row25[1:3] == ["45", "25"]
    col = {h: i for i, h in enumerate(header)}
    assert row15[col["T2 RMSE (mm)"]] == "0.0233"
    assert row15[col["T2 STE (s)"]] == "0.3660"
    assert row15[col["T7 RMSE (N)"]] == "0.0070"
    assert row15[col["T6 Amplitude ratio (-)"]] == "–"
    assert row25[col["T6 Phase shift (rad)"]] == "-0.0390"
    with pytest.raises(ValueError, match="W99-D45"):
        tables.table5_markdown(records, ["W99-D45"])


def test_long_table(records):
    md = tables.long_table_markdown(records)
    assert "| W10-D30 | 10 | 30 | T3 | 0.0141 | – | NaN |" in md
    extra = [_rec("a", 10, 45, "T5", rmse_mm=0.1, current_rmse_A=0.00213, contact=False)]
    md = tables.long_table_markdown(extra)
    assert "Current RMSE (A)" in md and "| a | 10 | 45 | T5 | 0.1000 | False | 0.0021 |" in md


def test_record_validation():
    with pytest.raises(ValueError, match=r"records\[0\]: missing key\(s\) test"):
        tables.table3_markdown([{"sample": "a", "wt_pct": 10, "diameter_mm": 45}])
    dup = [_rec("a", 10, 45, "T3", rmse_mm=0.1), _rec("a", 10, 45, "T3", rmse_mm=0.2)]
    with pytest.raises(ValueError, match="duplicate record for sample a test T3"):
        tables.table3_markdown(dup)


def _read_csv(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_write_tables_csv_round_trip(records, tmp_path):
    paths = tables.write_tables(records, tmp_path / "out", "res")
    names = sorted(p.name for p in paths)
    assert names == sorted(f"res_{n}.{e}" for n in ("long", "table3", "table4", "table5")
                           for e in ("csv", "md"))
    assert all(p.exists() and p.stat().st_size > 0 for p in paths)

    long_rows = _read_csv(tmp_path / "out" / "res_long.csv")
    assert len(long_rows) == len(records)
    cols = list(long_rows[0])
    assert cols[:4] == ["sample", "wt_pct", "diameter_mm", "test"]
    assert {"rmse_mm", "rmse_N", "ste_s", "amplitude_ratio", "phase_shift_rad"} <= set(cols)
    by_key = {(r["sample"], r["test"]): r for r in long_rows}
    for rec in records:
        row = by_key[(rec["sample"], rec["test"])]
        for k in ("rmse_mm", "rmse_N", "ste_s", "amplitude_ratio", "phase_shift_rad"):
            if k in rec:
                v = float(row[k])
                assert (math.isnan(v) and math.isnan(rec[k])) or v == rec[k]  # exact round trip
            else:
                assert row[k] == ""

    t3 = {r["diameter_mm"]: r for r in _read_csv(tmp_path / "out" / "res_table3.csv")}
    assert float(t3["45.0"]["T3_rmse_mm_mean"]) == pytest.approx(0.03)
    assert float(t3["45.0"]["T3_rmse_mm_std"]) == pytest.approx(_sd(0.01, 0.02, 0.06))
    assert t3["45.0"]["T3_rmse_mm_n"] == "3" and t3["45.0"]["n_samples"] == "3"
    assert t3["30.0"]["T3_rmse_mm_std"] == ""               # one value: no std
    assert t3["30.0"]["T3_ste_s_n_nonfinite"] == "1"
    t4 = _read_csv(tmp_path / "out" / "res_table4.csv")
    assert "T7_rmse_N_mean" in t4[0] and "T6_phase_shift_rad_std" in t4[0]
    t5 = _read_csv(tmp_path / "out" / "res_table5.csv")
    assert [r["sample"] for r in t5] == ["W15-D45", "W25-D45"]
    assert float(t5[0]["T7_rmse_N"]) == 0.007 and t5[0]["T1_rmse_mm"] == ""


def test_write_tables_numpy_values(tmp_path):
    recs = [_rec("W10-D45", np.int64(10), np.float64(45.0), "T3", rmse_mm=np.float64(0.1),
                 ste_s=np.float32(0.25))]
    paths = tables.write_tables(recs, tmp_path, "np")
    assert [p.name for p in paths if "table5" in p.name] == []   # no unseen sample
    row = _read_csv(tmp_path / "np_long.csv")[0]
    assert row["wt_pct"] == "10" and float(row["rmse_mm"]) == 0.1 and float(row["ste_s"]) == 0.25


def test_another_labs_fractions_are_summarized_not_left_empty(tmp_path):
    """No sample at the paper's 10/20/30 wt% (found by the property tests: header-only validation_table3.csv and
    validation_table4.csv): Tables 3 and 4 then summarize every sample; given summary_samples, exactly those."""
    recs = [_rec("W5-D25", 5, 25, "T3", rmse_mm=0.01, ste_s=0.1), _rec("W7-D25", 7, 25, "T3", rmse_mm=0.03, ste_s=0.3),
            _rec("W9-D45", 9, 45, "T3", rmse_mm=0.02, ste_s=0.2)]
    tables.write_tables(recs, tmp_path / "a", "v")
    with open(tmp_path / "a" / "v_table3.csv") as f:
        rows = list(csv.DictReader(f))
    by_d = {float(r["diameter_mm"]): r for r in rows}
    assert sorted(by_d) == [25.0, 45.0]
    assert float(by_d[25.0]["T3_rmse_mm_mean"]) == pytest.approx(0.02) and int(by_d[25.0]["n_samples"]) == 2
    assert "5, 7, 9 wt%" in (tmp_path / "a" / "v_table3.md").read_text()
    tables.write_tables(recs, tmp_path / "b", "v", summary_samples=["W9-D45"])
    with open(tmp_path / "b" / "v_table3.csv") as f:
        rows = list(csv.DictReader(f))
    assert [float(r["diameter_mm"]) for r in rows] == [45.0]
