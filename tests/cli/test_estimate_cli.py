"""`mpc-actuator estimate` (issue 26) and the estimator options of `control`: a T5 record of a heating sample
simulated with the model (true states known) and noise at the rig's floors, filtered from the command line into
estimate.csv (units in the column names) and a figure; the estimated velocity and winding temperature follow the
true ones. Bad options end in one `error:` line naming the option, exit code 1, nothing written."""
from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from fmu_src.model import ActuatorModel
from harness import cli
from harness.data import rig
from harness.data.dataset import Dataset, Sample, write_dataset
from harness.data.paramsjson import params_to_json
from harness.data.records import TimeSeries

GAP_MM = 5.0


def _heating_t5(tmp_path):
    """A one-sample dataset (T5 only, 1 kHz, 1.5 s) of W20-D45 with coil heating, its parameter file, and the true
    states (I, x, v, dT) per sample."""
    p = rig.apply_effects(rig.true_params(20, 45), {"coil_heating": 1.0}).with_(r0=GAP_MM / 1000.0)
    model = ActuatorModel(p, rtol=1e-10)
    t = np.arange(0.0, 1.5, 1e-3)
    V = np.where(t >= 0.2, 0.23 / p.kB * p.R, 0.0)
    truth = np.empty((t.size, 4))
    for k in range(t.size):
        truth[k] = model.integ.y
        if k + 1 < t.size:
            model.advance(t[k + 1], V[k])
    rng = np.random.default_rng(1)
    x_mm = rig.LASER.measure(truth[:, 1] * 1e3, rng)
    I = rig.CURRENT.measure(truth[:, 0], rng)
    rec = TimeSeries("T5", None, t, V, I, x_mm, None, 0.23, GAP_MM)
    ds = Dataset(root=None, synthetic=True, description="test", rig=rig.rig_description(),
                 samples=[Sample(id="W20-D45", wt_pct=20.0, diameter_mm=45.0, thickness_mm=1.5, tests={"T5": rec})])
    root = write_dataset(ds, tmp_path / "ds")
    pf = tmp_path / "params.json"
    pf.write_text(json.dumps({"samples": {"W20-D45": {"parameters": params_to_json(p)}}}))
    return root, pf, truth


def test_estimate_writes_velocity_and_temperature(tmp_path, capsys):
    root, pf, truth = _heating_t5(tmp_path)
    out = tmp_path / "est"
    cli.main(["estimate", str(root), "--params", str(pf), "--test", "T5", "--out", str(out)])
    assert "estimated I, x, v, dT" in capsys.readouterr().out
    assert (out / "figures" / "estimate.png").stat().st_size > 10_000
    with open(out / "estimate.csv") as f:
        rows = list(csv.DictReader(f))
    cols = rows[0].keys()
    for c in ("time_s", "V_V", "x_read_m", "I_read_A", "I_A", "x_m", "v_m_per_s", "dT_K", "std_v_m_per_s"):
        assert c in cols
    v = np.array([float(r["v_m_per_s"]) for r in rows])
    dT = np.array([float(r["dT_K"]) for r in rows])
    assert v.size == truth.shape[0]
    after = slice(400, None)   # after the step's transient
    assert np.sqrt(np.mean((v[after] - truth[after, 2]) ** 2)) < 1e-3        # mm/s-level velocity
    assert np.max(np.abs(dT - truth[:, 3])) < 0.1 * np.max(truth[:, 3])     # winding temperature within 10 %


@pytest.mark.parametrize("args, msg", [
    (["--test", "T7"], "--test must be one of"),
    (["--test", "T4"], "--test T4: sample W20-D45 of .* has no such test"),
    (["--test", "T5", "--noise-factor", "-1"], "--noise-factor must be"),
    (["--test", "T5", "--sample", "W10-D30"], "--sample"),
])
def test_estimate_bad_options(tmp_path, args, msg):
    root, pf, _ = _heating_t5(tmp_path)
    with pytest.raises(SystemExit, match=f"^error: {msg}"):
        cli.main(["estimate", str(root), "--params", str(pf), "--out", str(tmp_path / "o"), *args])
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("args, msg", [
    (["--offset-free"], "--offset-free needs --estimator ekf"),
    (["--noise-factor", "2"], "--noise-factor needs --estimator ekf"),
    (["--estimator", "ukf"], "--estimator must be one of none, ekf"),
])
def test_control_estimator_options_checked(tmp_path, args, msg):
    with pytest.raises(SystemExit, match=f"^error: {msg}"):
        cli.main(["control", "--out", str(tmp_path / "o"), *args])
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_control_with_the_offset_free_estimator(tmp_path, fmu_path, controller_fmu_path, capsys):
    out = tmp_path / "ctl"
    cli.main(["control", "--out", str(out), "--fmu", str(fmu_path), "--controller-fmu", str(controller_fmu_path),
              "--effect", "none", "--estimator", "ekf", "--offset-free", "--quiet"])
    md = (out / "control.md").read_text()
    assert "MPC+EKF offset-free" in md and "extended Kalman filter" in md
    with open(out / "control_metrics.csv") as f:
        rows = [r for r in csv.DictReader(f) if r["controller"] == "MPC+EKF offset-free"]
    assert {r["profile"] for r in rows} == {"stroke", "staircase"}
    stroke = next(r for r in rows if r["profile"] == "stroke")
    assert float(stroke["rmse_m"]) < 20e-6 and int(stroke["contact_events"]) == 0
