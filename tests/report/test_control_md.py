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


def test_the_first_mpc_call_is_reported_apart_from_the_per_step_solve_times():
    """Issue 21: the first call (8.1 s of compilation) was a per-step time. Hand-computed: the steps after it are
    1, 2, 3, 4, 100 ms: median 3 ms, p95 (linear, numpy's default) 4 + 0.8*96 = 80.8 ms, max 100 ms."""
    from harness.report.control_md import solve_stats, solve_time_line
    res = StudyResult([], {}, {}, [1e-3, 2e-3, 3e-3, 4e-3, 0.1], 5e-3, 20.0, first_call_s=8.1)
    line = solve_time_line(res, 0.01)
    assert "first call (numba compilation or cache loading: warm-up, not a control step): 8.10 s" in line
    assert "median 3.00 ms, 95th percentile 80.80 ms, max 100.00 ms" in line and "(5 steps)" in line
    st = solve_stats(res.solve_s)
    assert st == {"median": pytest.approx(3e-3), "p95": pytest.approx(80.8e-3), "max": pytest.approx(0.1), "steps": 5}
    assert solve_stats([])["steps"] == 0 and "no further steps" in solve_time_line(StudyResult([], {}, {}, [], 0, 0), 0.01)


def test_designs_that_miss_the_margins_are_named():
    from harness.control.tuning import PidGains
    from harness.report.control_md import margin_lines
    ok = PidGains(1.0, 1.0, 0.0, 0.002, 0.01, 50.0, 60.0, 3.0)
    short = PidGains(1.0, 1.0, 0.0, 0.002, 0.01, 5.0, 113.4, 2.47)
    res = StudyResult([], {}, {("paper", "stroke"): ok, ("paper", "staircase"): short}, [], 0, 0)
    lines = margin_lines(res)
    assert len(lines) == 1 and "paper model, staircase" in lines[0] and "gain margin 2.47" in lines[0]
