"""The command line's single jobs (harness.jobs): their checks on input, before any simulation."""
import json
from types import SimpleNamespace

import pytest

from fmu_src.specs import Params
from harness import jobs
from harness.data.dataset import DataFormatError


def test_true_params_need_virtual_rig_data(tmp_path):
    with pytest.raises(jobs.PipelineError, match="manifest.json has no rig.true_parameters"):
        jobs.true_params(SimpleNamespace(rig={}, root=tmp_path))


def test_true_params_drop_the_hidden_effects_unless_asked(tmp_path):
    tp = {"S": {"R_Ohm": 14.0, "L_H": 0.1, "Em_N_m_per_T2": 0.05, "K1_N_per_m3": 3e5, "K2_N_per_m": 35.0,
                "C_N_s_per_m": 0.45, "m_kg": 0.005, "a_m": 0.015, "kB_T_per_A": 0.29, "D_m": 0.045,
                "Rth_K_per_W": 8.0, "tau_th_s": 4.0}}
    ds = SimpleNamespace(rig={"true_parameters": tp}, root=tmp_path)
    paper = Params(R=14.0, L=0.1, Em=0.05, K1=3e5, K2=35.0, C=0.45, m=0.005)
    assert jobs.true_params(ds)["S"].with_(r0=paper.r0) == paper
    assert jobs.true_params(ds, with_effects=True)["S"].with_(r0=paper.r0) == paper.with_(Rth=8.0, tau_th=4.0)
    tp["S"]["m_kg"] = -1.0
    with pytest.raises(jobs.PipelineError, match=r"rig.true_parameters.S"):
        jobs.true_params(ds)


def test_parameter_file_errors_name_the_file(tmp_path):
    f = tmp_path / "broken.json"
    f.write_text("{not json")
    with pytest.raises(jobs.ParamsFileError, match="broken.json"):
        jobs.load_params_file(f)


def test_jobs_on_a_dataset_never_write_into_it(tmp_path):
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "manifest.json").write_text(json.dumps({"format": "mpc-actuator-data/1", "samples": []}))
    with pytest.raises(ValueError, match="inside the input dataset"):
        jobs.diagnose(ds, ds / "out")
    with pytest.raises(DataFormatError):
        jobs.check(ds)
    assert sorted(p.name for p in ds.iterdir()) == ["manifest.json"]


def _two_sample_dataset(root):
    """A small valid dataset with two samples (hand-written; T3 only)."""
    t3 = "time_s,voltage_V,current_A,displacement_mm\n0,0,0,0\n0.01,6,0.2,0.3\n0.02,6,0.3,0.4\n"
    tests = {"T3": {"file": None, "field_T": 0.11, "gap_mm": 9.0}}
    samples = []
    for sid in ("W20-D45", "W30-D60"):
        (root / sid).mkdir(parents=True)
        (root / sid / "T3.csv").write_text(t3)
        samples.append({"id": sid, "wt_pct": float(sid[1:3]), "diameter_mm": float(sid[-2:]), "thickness_mm": 1.5,
                        "tests": {"T3": dict(tests["T3"], file=f"{sid}/T3.csv")}})
    (root / "manifest.json").write_text(json.dumps({
        "format": "mpc-actuator-data/1", "synthetic": True,
        "rig": {"coil_radius_mm": 15.0, "field_per_amp_T_per_A": 0.29}, "samples": samples}))
    return root


def _params_file(path, *sample_ids):
    from harness.data.paramsjson import params_to_json
    p = Params(R=14.0, L=0.1, Em=0.05, K1=3e5, K2=35.0, C=0.45, m=0.005)
    path.write_text(json.dumps({sid: params_to_json(p) for sid in sample_ids}))
    return path


def test_protocols_refuses_samples_without_parameters_before_any_work(tmp_path, monkeypatch, capsys):
    from harness import cli

    def no_simulation(*a, **k):
        raise AssertionError("simulated before checking the parameter file")

    monkeypatch.setattr(jobs.validation, "run_dataset", no_simulation)
    ds = _two_sample_dataset(tmp_path / "ds")
    pf = _params_file(tmp_path / "one.json", "W20-D45", "W99-D45")
    with pytest.raises(SystemExit, match=r"^error: --params .*one.json has no parameters for 1 sample of the 2 of "
                                         r".*: W30-D60; pass --skip-missing to run only the 1 sample it has"):
        cli.main(["protocols", str(ds), "--out", str(tmp_path / "out"), "--params", str(pf), "--quiet"])
    assert not (tmp_path / "out").exists()
    with pytest.raises(SystemExit, match=r"^error: --params .*none\.json has parameters for none of the samples"):
        cli.main(["protocols", str(ds), "--out", str(tmp_path / "out"), "--quiet",
                  "--params", str(_params_file(tmp_path / "none.json", "W99-D45"))])


def test_protocols_skip_missing_runs_the_rest_and_says_so(tmp_path, monkeypatch, recwarn):
    seen = {}

    def record(ds, params, **kw):
        seen.update(params)
        raise KeyboardInterrupt                # stop before writing anything: only the choice is checked here

    monkeypatch.setattr(jobs.validation, "run_dataset", record)
    ds = _two_sample_dataset(tmp_path / "ds")
    pf = _params_file(tmp_path / "one.json", "W20-D45", "W99-D45")
    with pytest.raises(KeyboardInterrupt):
        jobs.protocols(ds, tmp_path / "out", pf, skip_missing=True)
    assert sorted(seen) == ["W20-D45"]
    msgs = [str(w.message) for w in recwarn if w.category is jobs.MissingParamsWarning]
    assert any("skipped 1 sample of" in m and "W30-D60" in m for m in msgs), msgs
    assert any("W99-D45" in m and "not used" in m for m in msgs), msgs
    assert not (tmp_path / "out").exists()


def test_protocol_tables_list_the_skipped_samples(tmp_path):
    from harness.analysis.validation.run import SampleRun
    rec = {"sample": "W20-D45", "wt_pct": 20.0, "diameter_mm": 45.0, "test": "T3", "rmse_mm": 0.1, "ste_s": 0.01}
    import numpy as np
    t = np.linspace(0.0, 0.1, 11)
    trace = {"time_s": t, "voltage_V": 6.0 + 0 * t, "current_A_meas": t, "current_A_sim": t, "y_meas": t,
             "y_sim": t, "quantity": "displacement_mm"}
    run = SampleRun(sample="W20-D45", records=[rec], traces={"T3": trace})
    written = jobs.write_protocol_outputs([run], tmp_path, synthetic=True,
                                          skipped={"W30-D60": "no parameters in --params one.json"})
    mds = [p for p in written if p.suffix == ".md"]
    assert mds and all("W30-D60" in p.read_text() and "no parameters" in p.read_text() for p in mds)


def _params_file_with(path, samples: dict):
    from harness.data.paramsjson import params_to_json
    path.write_text(json.dumps({"samples": {sid: {"parameters": params_to_json(p)} for sid, p in samples.items()}}))
    return path


P_A = Params(R=14.0, L=0.1, Em=0.05, K1=3e5, K2=35.0, C=0.45, m=0.005)
P_B = P_A.with_(Em=0.06, m=0.006)


def test_protocols_takes_each_samples_parameters_from_the_file_that_holds_it(tmp_path, monkeypatch, recwarn):
    """identification.json and generalization.json in one run (issue 21): W20-D45 from one file, W30-D60 from the
    other; a sample in both files with the same values is accepted."""
    seen = {}

    def record(ds, params, **kw):
        seen.update(params)
        raise KeyboardInterrupt                # only the choice is checked here

    monkeypatch.setattr(jobs.validation, "run_dataset", record)
    ds = _two_sample_dataset(tmp_path / "ds")
    ident = _params_file_with(tmp_path / "identification.json", {"W20-D45": P_A, "W99-D45": P_A})
    gen = _params_file_with(tmp_path / "generalization.json", {"W30-D60": P_B, "W99-D45": P_A})
    with pytest.raises(KeyboardInterrupt):
        jobs.protocols(ds, tmp_path / "out", [ident, gen])
    assert seen == {"W20-D45": P_A, "W30-D60": P_B}
    msgs = [str(w.message) for w in recwarn if w.category is jobs.MissingParamsWarning]
    assert any(f"--params {ident}, {gen} has parameters for W99-D45" in m for m in msgs), msgs


def test_protocols_refuses_a_sample_in_two_files_that_disagree(tmp_path, monkeypatch):
    from harness import cli

    def no_simulation(*a, **k):
        raise AssertionError("simulated before checking the parameter files")

    monkeypatch.setattr(jobs.validation, "run_dataset", no_simulation)
    ds = _two_sample_dataset(tmp_path / "ds")
    a = _params_file_with(tmp_path / "a.json", {"W20-D45": P_A, "W30-D60": P_A})
    b = _params_file_with(tmp_path / "b.json", {"W30-D60": P_B})
    with pytest.raises(SystemExit, match=r"^error: --params .*a\.json and .*b\.json both hold sample W30-D60, with "
                                         r"different parameters \(Em, m\); give it in one file only$") as e:
        cli.main(["protocols", str(ds), "--out", str(tmp_path / "out"), "--params", str(a), "--params", str(b),
                  "--quiet"])
    assert "\n" not in str(e.value.code) and not (tmp_path / "out").exists()


def test_protocols_skip_missing_with_several_files(tmp_path, monkeypatch, recwarn):
    seen = {}

    def record(ds, params, **kw):
        seen.update(params)
        raise KeyboardInterrupt

    monkeypatch.setattr(jobs.validation, "run_dataset", record)
    ds = _two_sample_dataset(tmp_path / "ds")
    a = _params_file_with(tmp_path / "a.json", {"W20-D45": P_A})
    b = _params_file_with(tmp_path / "b.json", {"W99-D45": P_B})
    with pytest.raises(jobs.PipelineError, match=r"--params .*a\.json, .*b\.json has no parameters for 1 sample"):
        jobs.protocols(ds, tmp_path / "out", [a, b])
    with pytest.raises(KeyboardInterrupt):
        jobs.protocols(ds, tmp_path / "out", [a, b], skip_missing=True)
    assert seen == {"W20-D45": P_A}
    msgs = [str(w.message) for w in recwarn if w.category is jobs.MissingParamsWarning]
    assert any("skipped 1 sample of" in m and "W30-D60" in m and "b.json" in m for m in msgs), msgs
