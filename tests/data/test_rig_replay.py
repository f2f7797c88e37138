"""Virtual rig (determinism, magnitudes, sensors), protocol runner through the FMU, cross-check references."""
import filecmp
import json
from pathlib import Path

import numpy as np
import pytest

from fmu_src.coil import voltage_for_field
from fmu_src.model import simulate
from harness.analysis.validation import crosscheck
from harness.analysis.validation import run as validation
from harness.data import protocol, rig
from harness.data.dataset import read_dataset
from harness.sim import virtual_rig

SAMPLES = [(10, 30), (20, 45), (30, 60), (30, 30)]


@pytest.fixture(scope="module")
def dataset(fmu_path, tmp_path_factory):
    out = tmp_path_factory.mktemp("ds") / "data"
    virtual_rig.generate_dataset(out, seed=7, samples=SAMPLES, fmu_path=fmu_path, workers=1, progress=False)
    return read_dataset(out)


def test_same_seed_same_bytes_other_seed_differs(fmu_path, tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    for d, seed in ((a, 3), (b, 3), (c, 4)):
        virtual_rig.generate_dataset(d, seed=seed, samples=[(20, 45)], fmu_path=fmu_path, workers=1, progress=False)
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert len(files) == 9
    for f in files:
        assert filecmp.cmp(a / f, b / f, shallow=False), f
    assert not filecmp.cmp(a / "W20-D45" / "T5.csv", c / "W20-D45" / "T5.csv", shallow=False)


def test_manifest_says_synthetic_and_documents_sensors(dataset):
    m = json.loads((dataset.root / "manifest.json").read_text())
    assert m["synthetic"] is True and "SYNTHETIC" in m["description"]
    assert m["rig"]["sensors"]["displacement_mm"]["noise_sigma"] == rig.LASER.sigma
    assert set(m["rig"]["true_parameters"]) == {rig.sample_id(*s) for s in SAMPLES}


def test_magnitudes_follow_the_paper(dataset):
    t1max = {s.id: s.tests["T1"].displacement_mm.max() for s in dataset.samples}
    t7max = {s.id: s.tests["T7"].force_N.max() for s in dataset.samples}
    # paper section 6.1: 30 wt% 60 mm reaches about 6.9 mm and 0.56 N (blocked, zero gap)
    assert 6.5 < t1max["W30-D60"] < 7.3
    assert 0.52 < t7max["W30-D60"] < 0.60
    assert dataset.sample("W30-D60").tests["T7"].force_N[-1] == pytest.approx(t7max["W30-D60"])  # max at 0 gap
    # both grow with filler fraction and diameter
    assert t1max["W10-D30"] < t1max["W20-D45"] < t1max["W30-D60"]
    assert t7max["W10-D30"] < t7max["W20-D45"] < t7max["W30-D60"]
    assert t1max["W30-D30"] < t1max["W30-D60"] and t7max["W30-D30"] < t7max["W30-D60"]
    # 30 mm samples saturate (Figure 4a): the peak is well below the gap (no contact)
    for sid in ("W10-D30", "W30-D30"):
        t1 = dataset.sample(sid).tests["T1"]
        k = int(np.argmax(t1.displacement_mm))
        assert t1.displacement_mm[k] < 0.8 * t1.gap_mm[k]
    # at 60 mm the diaphragm is pulled in to the coil at the gap of maximum displacement
    t1 = dataset.sample("W30-D60").tests["T1"]
    k = int(np.argmax(t1.displacement_mm))
    assert t1.displacement_mm[k] == pytest.approx(t1.gap_mm[k], abs=0.01)


def test_protocol_gaps_follow_table2(dataset):
    for s in dataset.samples:
        t1 = s.tests["T1"]
        g = t1.gap_mm[int(np.argmax(t1.displacement_mm))]
        assert [s.tests[n].gap_mm for n in ("T2", "T3", "T4", "T5", "T6", "T8")] == [g + 2] * 4 + [g + 3, 2.0]
        assert [s.tests[n].field_T for n in ("T2", "T3", "T4", "T5")] == [0.06, 0.11, 0.16, 0.23]
        assert list(t1.gap_mm) == list(range(25, -1, -1))
        ts = s.tests["T5"]
        assert ts.time_s[1] - ts.time_s[0] == pytest.approx(protocol.SAMPLE_PERIOD_S)
        assert ts.time_s[-1] >= 2.5 and protocol.step_onset(ts.time_s, ts.voltage_V).time_s == pytest.approx(protocol.PRE_STEP_S)


def test_sensor_noise_matches_documented_model(dataset):
    """Measured minus noise-free model output has the documented noise level (independent pure-Python run)."""
    s = dataset.sample("W20-D45")
    ts = s.tests["T5"]
    p = rig.true_params(20, 45).with_(r0=ts.gap_mm / 1000)
    clean = simulate(p, ts.time_s, ts.voltage_V)
    resid = ts.displacement_mm - clean["x"] * 1e3
    assert np.std(resid) == pytest.approx(rig.LASER.noise_floor, rel=0.1)
    assert np.allclose(np.round(ts.displacement_mm / rig.LASER.resolution) * rig.LASER.resolution, ts.displacement_mm)
    iresid = ts.current_A - clean["I"]
    assert np.std(iresid) == pytest.approx(rig.CURRENT.noise_floor, rel=0.1)
    assert ts.current_A[-500:].mean() == pytest.approx(voltage_for_field(0.23, p.kB, p.R) / p.R, rel=2e-3)


def test_unknown_effect_is_a_clear_error(fmu_path, tmp_path):
    with pytest.raises(ValueError, match="unknown effect"):
        virtual_rig.generate_dataset(tmp_path / "x", samples=[(20, 45)], fmu_path=fmu_path, effects={"warp_drive": 1.0},
                             workers=1, progress=False)


def test_full_protocol_run_of_one_sample(dataset, fmu_path):
    s = dataset.sample("W20-D45")
    truth = rig.true_params(20, 45)
    run = validation.run_sample(s, truth, rig=dataset.rig, fmu_path=fmu_path)
    rec = {r["test"]: r for r in run.records}
    assert set(rec) == {f"T{i}" for i in range(1, 9)}
    floor_mm, floor_N = rig.LASER.noise_floor, rig.FORCE.noise_floor
    for n in ("T2", "T3", "T4", "T5", "T6"):
        assert rec[n]["rmse_mm"] < 1.2 * floor_mm, n
        assert rec[n]["current_rmse_A"] < 1.2 * rig.CURRENT.noise_floor
    assert rec["T8"]["rmse_N"] < 1.2 * floor_N
    assert rec["T1"]["rmse_mm"] < 0.3 * floor_mm      # sweep points average 300 samples
    assert rec["T7"]["rmse_N"] < 0.3 * floor_N
    assert rec["T6"]["amplitude_ratio"] == pytest.approx(1.0, abs=0.01)
    assert abs(rec["T6"]["phase_shift_rad"]) < 0.01
    assert rec["T5"]["ste_s"] < 0.02 and rec["T8"]["ste_s"] < 0.02
    # wrong parameters are seen: 20 % more coupling is far outside the noise
    bad = validation.run_sample(s, truth.with_(Em=truth.Em * 1.2), rig=dataset.rig, fmu_path=fmu_path,
                               tests=("T5", "T7", "T8"))
    brec = {r["test"]: r for r in bad.records}
    assert brec["T5"]["rmse_mm"] > 5 * floor_mm and brec["T8"]["rmse_N"] > 5 * floor_N
    assert brec["T7"]["rmse_N"] > 5 * floor_N


def test_shipped_references_pass_and_detect_a_one_percent_change(fmu_path):
    ref = Path(__file__).resolve().parents[2] / "references" / "W20-D45"
    rep = crosscheck.check_references(ref, fmu_path=fmu_path)
    assert rep.passed, "\n".join(rep.lines())
    assert len(rep.results) == 20
    bad = crosscheck.check_references(ref, fmu_path=fmu_path, params_scale={"K2": 1.01})
    assert not bad.passed
