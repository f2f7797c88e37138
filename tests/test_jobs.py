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
