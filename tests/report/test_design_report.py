"""Files of `mpc-actuator design` (harness.report.design_report): values at three significant digits with
units, units in the CSV's column names, the front and the refined designs in the report."""
import csv
import json

import numpy as np

from harness.analysis.design.evaluate import METRICS
from harness.analysis.design.run import DesignResult, DesignSettings
from harness.analysis.design.space import Axis, DesignSpace, Targets
from harness.report import design_report as R


def test_sig_gives_three_significant_digits_without_an_exponent():
    assert [R.sig(v) for v in (28.1818, 5.45455, 0.0012345, 1234.6, 45.0, 0.0, None, float("inf"))] == \
        ["28.2", "5.45", "0.00123", "1235", "45.0", "0", "-", "inf"]


def _row(source, wt, power, p_lin):
    row = {"source": source, "wt_pct": wt, "diameter_mm": 45.4545, "gap_mm": 5.45455, "voltage_V": 4.70313}
    row.update({k: 0.001 for k in METRICS})
    row.update(contact=False, power_W=power, margin_pct=0.0001, probability_linearised=p_lin, probability_mc=None,
               probability_mc_se=None)
    if source == "refined":
        row["refined_from"] = "wt_pct 30, diameter_mm 45, gap_mm 5, voltage_V 5.4"
    return row


def test_report_tables_and_csv(tmp_path):
    sp = DesignSpace(Axis("wt_pct", 10, 30, 2), Axis("diameter_mm", 30, 60, 2), Axis("gap_mm", 5, 5, 1),
                     Axis("voltage_V", 2, 4, 2))
    m = {k: np.ones(sp.shape) for k in METRICS}
    m["contact"] = np.zeros(sp.shape, bool)
    cand = [_row("refined", 28.1818, 1.47463, 0.5), _row("grid", 30.0, 1.94, 0.99), _row("grid", 26.0, 1.94, 0.8)]
    res = DesignResult(sp, Targets(stroke_mm=1.0), m, np.ones(sp.shape, bool), cand, "hull",
                       DesignSettings(), front=[0, 1])
    R.write_design_outputs(res, tmp_path)
    md = (tmp_path / "design.md").read_text()
    assert "| 1 | refined | 28.2 | 45.5 | 5.45 | 4.70 | 1.47 |" in md
    assert "28.1818" not in md and "5.45455" not in md
    assert "**Minimised:** coil power [W] (`--minimise power`)" in md and "stroke >= 1.00 mm" in md
    front = md.split("## Trade-off front")[1]
    assert "| 2 | grid | 30.0 |" in front and "| 3 | grid |" not in front
    text = (tmp_path / "candidates.csv").read_text().splitlines()
    head = next(csv.reader(text))
    unitless = {"rank", "source", "contact", "on_front", "refined_from", "probability_linearised", "probability_mc",
                "probability_mc_se"}
    for c in head:
        assert c in unitless or c.rsplit("_", 1)[1] in {"pct", "mm", "V", "A", "W", "N", "m", "s", "Hz"}, c
    rows = list(csv.DictReader(text))
    assert [r["on_front"] for r in rows] == ["True", "True", "False"] and rows[0]["rank"] == "1"
    d = json.loads((tmp_path / "design.json").read_text())
    assert d["minimised_key"] == "power_W" and d["front"] == [0, 1] and d["designs_refined"] == 1
    assert (tmp_path / "figures/tradeoff_front.png").stat().st_size > 1000
