"""Smoke tests of harness.report.figures: every figure is a real PNG, bad input is named, no pyplot."""
import numpy as np
import pytest

from harness.report import figures


# --------------------------------------------------------------------------- plots
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _is_png(path, min_bytes=5000):
    data = path.read_bytes()
    return data[:8] == PNG_MAGIC and len(data) > min_bytes


def synthetic_runs(seed=0):
    """Synthetic measured/simulated runs of every test (first-order-like responses)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 1.0, 1e-3)
    runs = {}
    for test, V, A, tau in (("T2", 6.0, 0.6, 0.03), ("T3", 9.0, 1.4, 0.03),
                            ("T4", 12.0, 2.3, 0.025), ("T5", 18.0, 3.5, 0.02)):
        I = V / 15.0 * (1 - np.exp(-np.maximum(t - 0.1, 0) / 0.008)) * (t >= 0.1)
        y = A * (1 - np.exp(-np.maximum(t - 0.1, 0) / tau)) * (t >= 0.1)
        runs[test] = {"time_s": t, "voltage_V": V * (t >= 0.1),
                      "current_A_meas": I + 0.01 * rng.standard_normal(t.size),
                      "current_A_sim": I, "y_meas": y + 0.03 * rng.standard_normal(t.size),
                      "y_sim": 0.97 * y, "quantity": "displacement_mm"}
    t6 = np.arange(0.0, 5.0, 1e-3)
    runs["T6"] = {"time_s": t6, "voltage_V": 9 * (1 + np.sin(2 * np.pi * t6)),
                  "current_A_meas": 0.6 * (1 + np.sin(2 * np.pi * t6 - 0.05)),
                  "current_A_sim": 0.6 * (1 + np.sin(2 * np.pi * t6 - 0.05)),
                  "y_meas": 1.5 * (1 + np.sin(2 * np.pi * t6 - 0.3)) + 0.03 * rng.standard_normal(t6.size),
                  "y_sim": 1.4 * (1 + np.sin(2 * np.pi * t6 - 0.5)), "quantity": "displacement_mm"}
    gap = np.arange(0.0, 26.0, 1.0)
    runs["T1"] = {"gap_mm": gap, "y_meas": 4 * np.exp(-gap / 6) + 0.05 * rng.standard_normal(gap.size),
                  "y_sim": 4.1 * np.exp(-gap / 6.2), "quantity": "displacement_mm"}
    runs["T7"] = {"gap_mm": gap, "y_meas": 0.4 * np.exp(-gap / 5) + 0.005 * rng.standard_normal(gap.size),
                  "y_sim": 0.41 * np.exp(-gap / 5), "quantity": "force_N"}
    f = 0.3 * (1 - np.exp(-np.maximum(t - 0.1, 0) / 0.004) * (t >= 0.1)) * (t >= 0.1)
    runs["T8"] = {"time_s": t, "voltage_V": 18 * (t >= 0.1), "current_A_sim": runs["T5"]["current_A_sim"],
                  "y_meas": f + 0.003 * rng.standard_normal(t.size), "y_sim": f, "quantity": "force_N"}
    return runs


def test_plot_sample_figure(tmp_path):
    p = figures.plot_sample_figure(tmp_path / "sample.png", "W20-D45", synthetic_runs(), synthetic=True)
    assert p.exists() and _is_png(p, 50_000)
    # subset of tests, no current in T5
    runs = synthetic_runs()
    sub = {"T1": runs["T1"], "T5": {k: v for k, v in runs["T5"].items() if "current" not in k}}
    assert _is_png(figures.plot_sample_figure(tmp_path / "sub.png", "W10-D30", sub))
    with pytest.raises(ValueError, match="runs"):
        figures.plot_sample_figure(tmp_path / "none.png", "x", {})


def test_plot_default_step(tmp_path):
    t = np.linspace(0.0, 0.5, 501)
    i = 1.2 * (1 - np.exp(-t / 0.008))
    p = figures.plot_default_step(tmp_path / "default.png", figures.StepTraces(
        t, np.full_like(t, 18.0), i, 3.0 * (1 - np.exp(-t / 0.02)), 0.1 * i ** 2))
    assert _is_png(p)


def test_plot_residuals(tmp_path):
    runs = synthetic_runs()
    res = {k: (runs[k]["time_s"], runs[k]["y_sim"] - runs[k]["y_meas"]) for k in ("T3", "T5")}
    res["T1"] = (runs["T1"]["gap_mm"], runs["T1"]["y_sim"] - runs["T1"]["y_meas"])
    after = {k: (x, 0.5 * r) for k, (x, r) in res.items()}
    assert _is_png(figures.plot_residuals(tmp_path / "res.png", res, after))


def test_plot_surface(tmp_path):
    wt, d = np.meshgrid([10.0, 20.0, 30.0], [30.0, 45.0, 60.0])
    vals = 1e-3 * wt * d

    def grid_fn(W, D):
        return 1e-3 * W * D

    p = figures.plot_surface(tmp_path / "surf.png",
                             figures.SurfaceData("Em", "N.m/T^2", wt.ravel(), d.ravel(), vals.ravel()), grid_fn)
    assert _is_png(p)
    with pytest.raises(ValueError, match="grid_fn"):
        figures.plot_surface(tmp_path / "bad.png", figures.SurfaceData("Em", "-", wt.ravel(), d.ravel(),
                                                                        vals.ravel()), lambda W, D: np.zeros(3))
    with pytest.raises(ValueError, match="equal shape"):
        figures.plot_surface(tmp_path / "bad.png", figures.SurfaceData("Em", "-", [], [], []), grid_fn)


def test_plot_pareto(tmp_path):
    rng = np.random.default_rng(0)
    F = rng.random((40, 4))
    labels = ["T3 STE (s)", "T3 RMSE (mm)", "T5 STE (s)", "T5 RMSE (mm)"]
    assert _is_png(figures.plot_pareto(tmp_path / "pareto.png", F, 7, labels))
    with pytest.raises(ValueError, match="labels"):
        figures.plot_pareto(tmp_path / "p2.png", F, 0, labels[:3])


def test_plots_do_not_use_pyplot():
    assert not hasattr(figures, "plt")
    import sys
    if "matplotlib.pyplot" in sys.modules:  # imported by someone else: still no open figure
        assert sys.modules["matplotlib.pyplot"].get_fignums() == []
