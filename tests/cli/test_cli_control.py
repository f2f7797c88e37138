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
