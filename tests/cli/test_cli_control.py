"""`mpc-actuator control`: bad options end in one line naming them, before any work; the whole study end to end
(slow: about a minute on 2 cores)."""
from __future__ import annotations

import json

import pytest

from harness import cli


@pytest.mark.parametrize("args, msg", [
    (["--effect", "bogus"], r"^error: unknown effect 'bogus' \(known: coil_heating, "),
    (["--stroke-mm", "12"], r"^error: --stroke-mm 12 must be below the plant's gap r0 = 9 mm$"),
    (["--v-max", "-1"], r"^error: --v-max must be a finite number in \(0, 100\], got -1$"),
    (["--v-max", "-30"], r"^error: --v-max must be a finite number in \(0, 100\], got -30$"),
    (["--freq-hz", "0"], r"^error: --freq-hz must be a finite number in \[0.1, 10\], got 0$"),
    (["--freq-hz", "nan"], r"^error: --freq-hz must be a finite number in \[0.1, 10\], got nan$"),
    (["--margin-mm", "20"], r"^error: --margin-mm 20 plus --stroke-mm 1 must be below the plant's gap r0 = 9 mm "
                            r"\(the MPC keeps x <= r0 - margin = -11 mm\)$"),
    (["--margin-mm", "8", "--stroke-mm", "1"], r"^error: --margin-mm 8 plus --stroke-mm 1 must be below"),
    (["--margin-mm", "-0.1"], r"^error: --margin-mm must be a finite number >= 0, got -0.1$"),
    (["--controller-fmu", "nothere.fmu"], r"^error: controller FMU nothere.fmu not found; build it with "
                                          r"`python build_fmu.py --controller`$"),
])
def test_bad_options_are_one_line(tmp_path, args, msg):
    with pytest.raises(SystemExit, match=msg) as e:
        cli.main(["control", "--out", str(tmp_path / "out"), *args])
    assert "\n" not in str(e.value.code)
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_control_end_to_end(tmp_path, fmu_path, controller_fmu_path):
    out = tmp_path / "ctl"
    cli.main(["control", "--out", str(out), "--fmu", str(fmu_path), "--controller-fmu", str(controller_fmu_path),
              "--quiet"])
    doc = json.loads((out / "control.json").read_text())
    rows = {(r["plant"], r["model"], r["controller"], r["profile"]): r for r in doc["runs"]}
    assert len(rows) == 12 and all(r["contact_events"] == 0 for r in rows.values())
    assert rows[("clean", "paper", "MPC", "stroke")]["rmse_m"] < 20e-6
    imp = {(r["controller"], r["profile"]): r["ratio"] for r in doc["improvement"]}
    assert imp[("MPC", "stroke")] > 3.0   # the extended model pays off
    assert (out / "control.md").is_file() and len(list((out / "figures").glob("*.png"))) == 6


def test_the_study_refuses_a_margin_that_leaves_no_room_for_the_stroke():
    """The library's own check behind the command line's (a caller of harness.control.study directly)."""
    from harness.control.closedloop import ControlLoopError
    from harness.control.mpc import MpcSettings
    from harness.control.study import StudySettings
    with pytest.raises(ControlLoopError, match=r"MPC margin_m 0.02 plus stroke_m 0.001 \[m\] must be below r0"):
        StudySettings(actuator_fmu="", controller_fmu="", mpc=MpcSettings(margin_m=0.02))


@pytest.mark.slow
def test_control_on_a_diagnosed_sample_clips_and_reports(tmp_path, fmu_path, controller_fmu_path, capsys):
    """Issue 21: a diagnosis's extended_params.json (filler saturation ksat = 5.53 1/T^2, lam = 0.54) on the rig's
    W20-D45: the controllers initialise, the staircase beyond the saturating plant's holdable range is clipped with
    one warning line, and the range's end is the independent static inverse's V = V_max point."""
    import math
    import sys
    from pathlib import Path

    from scipy.optimize import brentq

    from harness.data import rig
    from harness.data.paramsjson import params_to_json
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "independent"))
    from physics import kernel_G

    base = rig.true_params(20, 45)
    f = tmp_path / "extended_params.json"
    f.write_text(json.dumps({"samples": {"W20-D45": {"parameters": params_to_json(base.with_(ksat=5.53, lam=0.54))},
                                         "W30-D60": {"parameters": params_to_json(rig.true_params(30, 60))}}}))
    out = tmp_path / "ctl"
    cli.main(["control", "--out", str(out), "--fmu", str(fmu_path), "--controller-fmu", str(controller_fmu_path),
              "--params", str(f), "--sample", "W20-D45", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: ") and "clipped to" in err[0], err
    doc = json.loads((out / "control.json").read_text())
    p = base

    def v_hold(x):
        K = (p.K1 * x * x + p.K2) * x
        return p.R * math.sqrt(K / (p.Em * kernel_G(p.r0 - x, p.a, p.D, p.kB) - 5.53 * p.kB ** 2 * K))
    x_v = brentq(lambda x: v_hold(x) - 30.0, 1e-5, 2.4e-3, xtol=1e-13)   # below the saturated limit, 2.42 mm
    rng = doc["holdable_range"]["filler_saturation+motional_emf"]
    assert rng["x_holdable_m"] == pytest.approx(x_v, rel=1e-6) and rng["limited_by"] == "voltage limit"
    assert "W20-D45" in doc["sample"] and len(doc["runs"]) == 12
    assert all(r["contact_events"] == 0 for r in doc["runs"])
    assert doc["mpc_solve_time_s"]["steps"] > 0 and doc["mpc_first_call_s"] is not None
    assert "Setpoints clipped" in (out / "control.md").read_text()
