"""A fit that cannot converge within its budget is reported, never run on (issue "Any valid dataset").

``DiagnoseSettings.fit_budget_s`` bounds the wall time of each fit phase: no Levenberg-Marquardt iteration starts
after it. Here the budget is spent before the first iteration, so that every fit stops at its start point: the
diagnosis must still finish, and ``diagnosis.json``/``diagnosis.md`` must list the fits it cut short and why.
"""
from __future__ import annotations

import json

from harness.analysis.diagnosis import DiagnoseSettings, diagnose
from harness.data.dataset import read_dataset
from harness.report.diagnosis_md import write_diagnosis
from tests.analysis.diagnosis.test_residual_layout import FIXTURE


def test_fits_cut_short_by_the_budget_are_reported(tmp_path):
    st = DiagnoseSettings(workers=1, fit_budget_s=1e-9)
    d = diagnose(read_dataset(FIXTURE), st)
    cs = d.fits_cut_short
    assert cs, "a budget spent before the first iteration must cut every fit short"
    assert {c["stop"] for c in cs} == {"time_budget"} and all(c["iterations"] == 0 for c in cs)
    models = {c["model"] for c in cs}
    assert "paper model (refit)" in models and len(models) > 1          # the refit and the candidates
    assert all("fit_budget_s" in c["why"] for c in cs)
    write_diagnosis(d, tmp_path)
    data = json.loads((tmp_path / "diagnosis.json").read_text())
    assert len(data["fits_cut_short"]) == len(cs) and data["settings"]["fit_budget_s"] == 1e-9
    md = (tmp_path / "diagnosis.md").read_text()
    assert "## Fits cut short" in md and "time budget" in md


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
