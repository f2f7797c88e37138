"""Command line of `mpc-actuator design` and `uncertainty`: one clear error line before any work."""
import json

import numpy as np
import pytest

from harness import cli
from harness.analysis.identification import parameter_uncertainty as U
from harness.data import rig


def _uncertainty_file(tmp_path):
    uncs = {}
    for w, d in rig.TRAINING_SAMPLES:
        p = rig.true_params(w, d)
        sid = rig.sample_id(w, d)
        uncs[sid] = U.ParameterUncertainty(sid, float(w), float(d), p, np.diag((0.01 * np.array(
            [getattr(p, n) for n in U.PARAMS])) ** 2))
    f = tmp_path / "in" / "uncertainty.json"
    f.parent.mkdir()
    f.write_text(json.dumps(U.uncertainty_to_json(uncs)))
    return f


def _error(args, capsys=None):
    with pytest.raises(SystemExit) as e:
        cli.main(args)
    return str(e.value.code)


def test_design_errors_name_the_option_and_leave_nothing(tmp_path):
    f = _uncertainty_file(tmp_path)
    out = tmp_path / "out"
    msg = _error(["design", "--uncertainty", str(f), "--out", str(out)])
    assert msg.startswith("error: no target given: name at least one of --stroke-mm")
    msg = _error(["design", "--uncertainty", str(f), "--out", str(out), "--stroke-mm", "1", "--wt-pct", "5", "30"])
    assert msg.startswith("error: (wt_pct=5, diameter_mm=30) lies outside the convex hull of the identified samples")
    assert "do not extrapolate" in msg and not out.exists()
    msg = _error(["design", "--uncertainty", str(tmp_path / "nope.json"), "--out", str(out), "--stroke-mm", "1"])
    assert msg.startswith("error: ") and "nope.json: cannot read" in msg
    msg = _error(["design", "--uncertainty", str(f), "--out", str(f.parent), "--stroke-mm", "1", "--overwrite"])
    assert msg.startswith("error: --out ")
    assert f.exists()
    msg = _error(["design", "--uncertainty", str(f), "--out", str(out), "--stroke-mm", "-2"])
    assert msg == "error: --stroke-mm must be a finite number > 0, got -2"
    msg = _error(["design", "--uncertainty", str(f), "--out", str(out), "--stroke-mm", "1", "--gap-mm", "12", "3"])
    assert msg == "error: --gap-mm 12 3: a range is given low then high (did you mean --gap-mm 3 12?)"
    assert not out.exists()


def test_a_range_given_high_low_is_refused_by_the_design_space_too():
    from harness.analysis.design.space import Axis, DesignError
    with pytest.raises(DesignError, match=r"^--voltage-V 12 1: a range is given low then high"):
        Axis.parse("voltage_V", [12, 1], 5)
    assert Axis.parse("voltage_V", [1, 12], 5).values[0] == 1.0 and Axis.parse("gap_mm", [4, 4], 5).n == 1


def test_uncertainty_needs_a_parameter_file_with_samples_of_the_dataset(tmp_path):
    msg = _error(["uncertainty", str(tmp_path / "no-dataset"), "--params", str(tmp_path / "p.json"),
                  "--out", str(tmp_path / "o")])
    assert msg.startswith("error: ") and "no-dataset" in msg


def test_an_unknown_objective_is_one_line_naming_the_option(tmp_path, capsys):
    f = _uncertainty_file(tmp_path)
    out = tmp_path / "out"
    msg = _error(["design", "--uncertainty", str(f), "--out", str(out), "--stroke-mm", "1", "--minimise", "mass"])
    assert msg == "error: --minimise must be one of power, current, diameter, filler, got 'mass'"
    msg = _error(["design", "--uncertainty", str(f), "--out", str(out), "--stroke-mm", "1", "--min-probability", "1"])
    assert msg == "error: --min-probability must be a finite number in [0, 1), got 1"
    assert not out.exists()


def test_an_infeasible_spec_writes_the_nearest_designs_and_exits_with_an_error(tmp_path):
    """No design of the grid reaches a 50 mm stroke (the gaps are 3-12 mm): exit code 1 with one line, and a
    report listing the nearest designs and that each misses --stroke-mm."""
    f = _uncertainty_file(tmp_path)
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as e:
        cli.main(["design", "--uncertainty", str(f), "--out", str(out), "--stroke-mm", "50", "--points", "2",
                  "--draws", "2", "--workers", "1", "--quiet"])
    msg = str(e.value.code)
    assert msg.startswith("error: no design of the 16 in the space meets the spec; the 10 nearest")
    assert msg.endswith(f"{out / 'design.md'}")
    md = (out / "design.md").read_text()
    assert "**No design of the 16 in the space meets the spec**" in md
    d = json.loads((out / "design.json").read_text())
    assert d["candidates"] == [] and len(d["nearest"]) == 10
    for r in d["nearest"]:
        assert [m["option"] for m in r["misses"]][0] == "--stroke-mm" and r["misses"][0]["limit"] == 50.0
        assert r["misses"][0]["value"] == pytest.approx(r["stroke_m"] * 1e3)
    margins = [r["margin_pct"] for r in d["nearest"]]
    assert margins == sorted(margins, reverse=True) and margins[0] < 0
