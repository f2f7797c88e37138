"""Files of `mpc-actuator uncertainty` and `design` (harness.report.uncertainty_report): tables with units in
the column names, JSON without NaN/Infinity, figures written."""
import csv
import json

import numpy as np

from harness.analysis.identification import parameter_uncertainty as U
from harness.analysis.uncertainty.bands import Band
from harness.analysis.design.evaluate import METRICS
from harness.analysis.design.run import DesignResult, DesignSettings
from harness.analysis.design.space import Axis, DesignSpace, Targets
from harness.analysis.uncertainty.run import UncertaintyResult, UncertaintySettings
from harness.data import rig
from harness.report import uncertainty_report as R


def test_uncertainty_outputs(tmp_path):
    p = rig.true_params(20, 45)
    mean = np.array([getattr(p, n) for n in U.PARAMS])
    u = U.ParameterUncertainty("W20-D45", 20.0, 45.0, p, np.diag((0.01 * mean) ** 2),
                               {n: (0.98 * v, 1.02 * v) for n, v in zip(U.PARAMS, mean)}, {n: "m" for n in U.PARAMS})
    t = np.linspace(0, 1, 11)
    b = Band("T5", "displacement_mm", "time_s", t, t * 0.9, t, t * 1.1, t, 0.005, 100.0)
    res = UncertaintyResult({"W20-D45": u}, {}, {"W20-D45": {"T5": b}}, {}, UncertaintySettings())
    written = R.write_uncertainty_outputs(res, tmp_path)
    names = {w.relative_to(tmp_path).as_posix() for w in written}
    assert {"uncertainty.json", "parameter_uncertainty.md", "prediction_bands.csv", "bands/W20-D45/T5.csv",
            "figures/bands_W20-D45.png"} <= names
    rows = list(csv.DictReader(open(tmp_path / "parameter_uncertainty.csv")))
    k1 = [r for r in rows if r["parameter"] == "K1_N_per_m3"][0]
    assert float(k1["std_pct"]) == 1.0 and float(k1["ci95_lo"]) < float(k1["value"]) < float(k1["ci95_hi"])
    band = list(csv.DictReader(open(tmp_path / "bands/W20-D45/T5.csv")))
    assert list(band[0]) == ["time_s", "p2.5_mm", "p50_mm", "p97.5_mm", "measured_mm"] and len(band) == 11
    assert U.read_uncertainty(tmp_path / "uncertainty.json")["W20-D45"].cov[3, 3] == u.cov[3, 3]


def test_design_outputs_write_infinite_settling_as_null(tmp_path):
    sp = DesignSpace(Axis("wt_pct", 10, 30, 2), Axis("diameter_mm", 30, 60, 2), Axis("gap_mm", 5, 5, 1),
                     Axis("voltage_V", 2, 4, 2))
    m = {k: np.ones(sp.shape) for k in METRICS}
    m["contact"] = np.zeros(sp.shape, bool)
    m["settling_s"][0, 0, 0, 0] = np.inf
    feas = np.zeros(sp.shape, bool)
    feas[1, 1, 0, 1] = feas[0, 0, 0, 0] = True
    cand = []
    for c in np.argwhere(feas):
        row = {"source": "grid", "wt_pct": 1.0, "diameter_mm": 1.0, "gap_mm": 5.0, "voltage_V": 2.0}
        row.update({k: (bool(m[k][tuple(c)]) if k == "contact" else float(m[k][tuple(c)])) for k in METRICS})
        row.update(margin_pct=10.0, probability_linearised=0.5, probability_mc=0.5, probability_mc_se=0.1)
        cand.append(row)
    res = DesignResult(sp, Targets(stroke_mm=0.1), m, feas, cand, "hull", DesignSettings(), front=[0, 1])
    written = R.write_design_outputs(res, tmp_path)
    d = json.loads((tmp_path / "design.json").read_text())
    assert d["designs_evaluated"] == 8 and d["designs_feasible"] == 2
    assert d["candidates"][0]["settling_s"] is None and d["candidates"][1]["settling_s"] == 1.0
    assert (tmp_path / "figures/feasible_region.png").stat().st_size > 1000
    assert len(written) == 6
