"""`mpc-actuator control`: bad options end in one line naming them, before any work; the whole study end to end
(slow: about a minute on 2 cores)."""
from __future__ import annotations

import json

import pytest

from harness import cli


@pytest.mark.parametrize("args, msg", [
    (["--effect", "bogus"], r"^error: unknown effect 'bogus' \(known: coil_heating, "),
    (["--stroke-mm", "12"], r"^error: stroke \[m\] must be in \(0, r0 = 0.009\), got 0.012$"),
    (["--v-max", "-1"], r"^error: MpcSettings: V_max_V -1.0 must be > V_min_V 0.0$"),
    (["--controller-fmu", "nothere.fmu"], r"^error: controller FMU nothere.fmu not found; build it with "
                                          r"`python build_fmu.py --controller`$"),
])
def test_bad_options_are_one_line(tmp_path, args, msg):
    with pytest.raises(SystemExit, match=msg):
        cli.main(["control", "--out", str(tmp_path / "out"), *args])
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
