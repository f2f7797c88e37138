"""Command line: baking parameters into an FMU, output-folder guards, clear errors."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fmu_src.model import simulate
from fmu_src.specs import Params
from harness import cli

REPO = Path(__file__).resolve().parents[1]


def _params_file(tmp_path, **extra):
    d = {"R_Ohm": 14.0, "L_H": 0.1, "Em_N_m_per_T2": {"value": 0.05, "uncertainty": 0.001}, "K1_N_per_m3": 3e5,
         "K2_N_per_m": 35.0, "C_N_s_per_m": 0.45, "m_kg": 0.005, "a_m": 0.015, "kB_T_per_A": 0.29, "D_m": 0.045}
    d.update(extra)
    f = tmp_path / "params.json"
    f.write_text(json.dumps({"samples": {"W20-D45": {"parameters": d}}}))
    return f


def test_build_bakes_parameters_and_effects(tmp_path):
    pf = _params_file(tmp_path, Rth_K_per_W=8.0, tau_th_s=4.0)
    out = tmp_path / "baked.fmu"
    # a separate interpreter: the FMU must load its own shipped copy of the physics
    proc = subprocess.run([sys.executable, "-m", "harness.cli", "build", "--params", str(pf), "--gap-mm", "6",
                           "--out", str(out)], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    code = f"""
import fmpy, json, numpy as np
md = fmpy.read_model_description({str(out)!r}, validate=True)
start = {{v.name: v.start for v in md.modelVariables}}
r = fmpy.simulate_fmu({str(out)!r}, stop_time=1.0, output_interval=1e-3, output=['x', 'I'])
print(json.dumps({{'start': start, 'x': r['x'].tolist(), 'I': r['I'].tolist()}}))
"""
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    s = got["start"]
    assert float(s["r0"]) == 0.006 and float(s["Em"]) == 0.05 and float(s["Rth"]) == 8.0 and float(s["R"]) == 14.0
    assert float(s["V"]) == pytest.approx(0.23 / 0.29 * 14.0)
    p = Params(R=14.0, L=0.1, Em=0.05, K1=3e5, K2=35.0, C=0.45, m=0.005, r0=0.006, Rth=8.0, tau_th=4.0)
    t = np.arange(1001) * 1e-3
    py = simulate(p, t, 0.23 / 0.29 * 14.0)
    assert np.max(np.abs(np.array(got["x"]) - py["x"])) < 1e-9 * np.max(np.abs(py["x"]))
    # heating is really on: the current droops below the cold steady value V/R
    assert got["I"][-1] < 0.99 * 0.23 / 0.29


def test_build_rejects_bad_parameters_by_name(tmp_path):
    pf = _params_file(tmp_path, m_kg=-1.0)
    with pytest.raises(SystemExit, match=r"W20-D45: parameter m \[kg\] must be > 0"):
        cli.main(["build", "--params", str(pf), "--out", str(tmp_path / "x.fmu")])
    assert not (tmp_path / "x.fmu").exists()
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(SystemExit, match="broken.json"):
        cli.main(["build", "--params", str(tmp_path / "broken.json"), "--out", str(tmp_path / "x.fmu")])


def test_out_folder_guards(tmp_path):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "thesis.tex").write_text("precious")
    with pytest.raises(SystemExit, match="not empty"):
        cli._out_dir(str(user), overwrite=False)
    with pytest.raises(SystemExit, match="not made by mpc-actuator"):
        cli._out_dir(str(user), overwrite=True)
    assert (user / "thesis.tex").read_text() == "precious"
    ours = cli._out_dir(str(tmp_path / "run"), overwrite=False)
    (ours / "table.md").write_text("x")
    assert cli._out_dir(str(ours), overwrite=True) == ours       # our own folder may be reused
    ds = tmp_path / "dataset"
    ds.mkdir()
    with pytest.raises(SystemExit, match="inside the input dataset"):
        cli._guard_not_inside(ds / "results", ds)


def test_check_names_the_broken_file(tmp_path, capsys):
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "manifest.json").write_text(json.dumps({
        "format": "mpc-actuator-data/1", "synthetic": True,
        "samples": [{"id": "S", "wt_pct": 20, "diameter_mm": 45, "thickness_mm": 1.5,
                     "tests": {"T5": {"file": "S/T5.csv", "field_T": 0.23, "gap_mm": 5.0}}}]}))
    (ds / "S").mkdir()
    (ds / "S" / "T5.csv").write_text("time_s,voltage_V,current_A,displacment_mm\n0,0,0,0\n0.001,1,0.1,0\n")
    with pytest.raises(SystemExit) as e:
        cli.main(["check", str(ds)])
    msg = str(e.value)
    assert "T5.csv" in msg and "displacement_mm" in msg
