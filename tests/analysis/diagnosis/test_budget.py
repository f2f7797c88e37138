"""A fit that cannot converge within its budget is reported, never run on (issue "Any valid dataset").

``DiagnoseSettings.fit_budget_s`` bounds the CPU time of the diagnosis's fits (``harness.analysis.core.cpu_clock``):
no Levenberg-Marquardt iteration starts after it. Here the budget is spent before the first iteration, so that every fit stops at its start point: the
diagnosis must still finish, and ``diagnosis.json``/``diagnosis.md`` must list the fits it cut short and why.
"""
from __future__ import annotations

import json

from harness.analysis.diagnosis import DiagnoseSettings
from harness.report.diagnosis_md import write_diagnosis
from tests.analysis.diagnosis.test_residual_layout import FIXTURE


def test_fits_cut_short_by_the_budget_are_reported(tmp_path):
    """Through ``harness.jobs.diagnose`` (what ``diagnose --fit-budget-s`` calls) with a budget spent at once."""
    from harness import jobs
    from harness.pipeline import JobSettings
    d, _ = jobs.diagnose(FIXTURE, tmp_path / "job", job=JobSettings(workers=1, progress=False), fit_budget_s=1e-9)
    cs = d.fits_cut_short
    assert cs, "a budget spent before the first iteration must cut every fit short"
    assert {c["stop"] for c in cs} == {"time_budget"} and all(c["iterations"] == 0 for c in cs)
    models = {c["model"] for c in cs}
    assert "paper model (refit)" in models and len(models) > 1          # the refit and the candidates
    assert all("fit_budget_s" in c["why"] and "CPU" in c["why"] for c in cs)
    write_diagnosis(d, tmp_path)
    data = json.loads((tmp_path / "diagnosis.json").read_text())
    assert len(data["fits_cut_short"]) == len(cs) and data["settings"]["fit_budget_s"] == 1e-9
    md = (tmp_path / "diagnosis.md").read_text()
    assert "## Fits cut short" in md and "time budget" in md


def test_a_bad_budget_option_is_one_line_naming_it(tmp_path, capsys):
    import pytest
    from harness import cli
    for bad in ("0", "-3", "nan", "x"):
        with pytest.raises(SystemExit) as e:
            cli.main(["diagnose", str(FIXTURE), "--out", str(tmp_path / "o"), "--fit-budget-s", bad])
        # one line: the SystemExit's message (the interpreter prints it and exits 1) or argparse's last line (2)
        msg = e.value.code if isinstance(e.value.code, str) else capsys.readouterr().err.strip().splitlines()[-1]
        assert e.value.code != 0 and msg.startswith(("error:", "mpc-actuator")) and "--fit-budget-s" in msg, msg
        assert "must be a finite number > 0" in msg, msg       # the option's own check, not argparse's
    assert not (tmp_path / "o").exists()
    # a valid value reaches the diagnosis's settings
    args = cli.build_parser().parse_args(["diagnose", str(FIXTURE), "--out", "o", "--fit-budget-s", "12.5"])
    assert args.fit_budget_s == 12.5


def test_the_budget_is_a_validated_setting():
    import pytest
    from harness.analysis.diagnosis.settings import DiagnoseSettingsError
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(DiagnoseSettingsError, match="fit_budget_s"):
            DiagnoseSettings(fit_budget_s=bad)


def test_the_terminal_summary_warns_when_the_budget_cut_fits_short():
    from types import SimpleNamespace
    from harness.pipeline import summary_lines
    cut = [{"model": "paper model (refit)", "fit": "x", "stop": "time_budget", "iterations": 0, "why": "..."},
           {"model": "sensor_lag", "fit": "y", "stop": "max_iter", "iterations": 20, "why": "..."}]
    d = SimpleNamespace(cause="unexplained", verdict="unexplained", causes=[], gain={}, fits_cut_short=cut)
    lines = summary_lines(d)
    assert any(ln.strip().startswith("warning: 1 fit(s) stopped on the time budget") for ln in lines)
    assert not any("warning" in ln for ln in summary_lines(SimpleNamespace(**{**d.__dict__, "fits_cut_short": cut[1:]})))


def test_the_terminal_summary_names_the_candidates_the_budget_left_undecided():
    from types import SimpleNamespace
    from harness.pipeline import summary_lines
    rem = {"present": True, "undecided_within_budget": [{"candidate": "coil_heating", "iterations": 2}]}
    d = SimpleNamespace(cause="unexplained", verdict="unexplained", causes=[], gain={}, fits_cut_short=[],
                        remainder=rem)
    lines = [ln.strip() for ln in summary_lines(d)]
    assert any(ln.startswith("not decided within the fit budget: coil_heating (cut after 2 iteration(s))")
               for ln in lines), lines
    none = SimpleNamespace(**{**d.__dict__, "remainder": {"present": True, "undecided_within_budget": []}})
    assert not any("not decided" in ln for ln in summary_lines(none))
