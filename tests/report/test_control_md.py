"""harness.report.control_md: the figures are written, the improvement table pairs the right runs."""
from __future__ import annotations

import pytest

from fmu_src.specs import Params
from harness.control.study import StudyResult
from harness.report.control_md import improvement_rows, plot_linearization, plot_operating_map


def test_figures_are_written(tmp_path):
    p = Params()
    for f in (plot_operating_map(tmp_path / "m.png", p, [0.005, 0.009]),
              plot_linearization(tmp_path / "l.png", p, [1e-3, 3e-3])):
        assert f.is_file() and f.stat().st_size > 10_000


def test_improvement_rows():
    def row(plant, model, ctl, prof, rmse):
        return {"plant": plant, "model": model, "controller": ctl, "profile": prof, "rmse_m": rmse}
    rows = [row("clean", "paper", "MPC", "stroke", 1.0), row("sat", "paper", "MPC", "stroke", 8.0),
            row("sat", "extended", "MPC", "stroke", 2.0), row("sat", "paper", "PI", "stroke", 3.0)]
    res = StudyResult(rows, {}, {}, [], 5e-3, 20.0)
    assert improvement_rows(res) == [{"plant": "sat", "controller": "MPC", "profile": "stroke", "rmse_paper_m": 8.0,
                                      "rmse_extended_m": 2.0, "ratio": pytest.approx(4.0)}]
