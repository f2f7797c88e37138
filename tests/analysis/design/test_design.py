"""Inverse design (harness.analysis.design): the evaluation kernel against independent solvers, targets
and space validation, the hull refusal, and the whole search on a local Dask cluster (identical results for
1 and 2 workers with the same seed)."""
import numpy as np
import pytest
from scipy.optimize import brentq

from fmu_src.model import simulate as model_simulate
from harness.analysis.identification import parameter_uncertainty as U
from harness.analysis.design import evaluate as E
from harness.analysis.design.run import DesignSettings, default_space, design, nominal_params, surface_model
from harness.analysis.design.space import Axis, DesignError, Targets
from harness.analysis.core.sweep import ClusterSettings
from harness.data import rig
from harness.sim.kernels import kernel

P = rig.true_params(20, 45)
FIT = ("Em", "K1", "K2", "C", "m")


def _block(V, gap=0.009, scale=None):
    n = len(V)
    scale = np.ones(n) if scale is None else np.asarray(scale)
    par = {k: np.full(n, getattr(P, k)) for k in FIT}
    par["Em"] = par["Em"] * scale
    return E.Block(a_m=P.a, kB_T_per_A=P.kB, R_Ohm=P.R, L_H=P.L, D_m=P.D, gap_m=gap, V_V=np.asarray(V, float),
                   params=par, t_step_s=0.6)


def test_static_point_equals_a_scalar_root_find_and_detects_pull_in():
    G = kernel(P.a, P.D, P.kB, 0.004)
    I = np.array([0.1, 0.3, 0.5, 5.0])
    EmI2 = P.Em * I ** 2
    x, pulled = E.static_point(G, 0.004, EmI2, np.full(4, P.K1), np.full(4, P.K2))
    for k in range(3):
        ref = brentq(lambda z: EmI2[k] * G(0.004 - z) - (P.K1 * z ** 3 + P.K2 * z), 0.0, 0.004 * 0.999, xtol=1e-15)
        assert x[k] == pytest.approx(ref, rel=0, abs=1e-12)
        assert not pulled[k]
    # 5 A at a 4 mm gap: the magnetic force exceeds the spring at every x: pulled in
    xs = np.linspace(0, 0.004, 400)
    assert np.all(EmI2[3] * np.array([G(0.004 - z) for z in xs]) > P.K1 * xs ** 3 + P.K2 * xs)
    assert pulled[3] and x[3] == 0.004


def test_step_response_metrics_agree_with_the_compiled_integrator():
    V = np.array([3.0, 6.0, 9.0])
    m = E.evaluate_block(_block(V))
    t = np.arange(0, 0.6 + 5e-4, 1e-3)
    for k, v in enumerate(V):
        r = model_simulate(P.with_(r0=0.009), t, np.full(t.size, v))
        x = r["x"]
        assert m["stroke_m"][k] == pytest.approx(x[-1], rel=1e-4)
        assert m["static_stroke_m"][k] == pytest.approx(x[-1], rel=1e-4)
        out = np.abs(x - x[-1]) > 0.02 * abs(x[-1])
        ts = t[np.flatnonzero(out)[-1] + 1]
        assert abs(m["settling_s"][k] - ts) <= 2e-3
        assert m["current_A"][k] == pytest.approx(v / P.R)
        assert m["blocked_force_N"][k] == pytest.approx(P.Em * (v / P.R) ** 2 * kernel(P.a, P.D, P.kB, 0.009)(0.009))
    assert not m["contact"].any()


def test_targets_and_axes_are_validated_with_the_option_named():
    with pytest.raises(DesignError, match="no target given"):
        Targets()
    with pytest.raises(DesignError, match=r"--stroke-mm must be a finite number > 0"):
        Targets(stroke_mm=-1)
    with pytest.raises(DesignError, match=r"--gap-mm: give one value \(fixed\) or two"):
        Axis.parse("gap_mm", [1, 2, 3], 5)
    t = Targets(stroke_mm=0.5, max_power_W=2.0)
    m = {"current_A": np.array([0.1, 0.1, 0.1]), "power_W": np.array([1.0, 3.0, 1.0]),
         "stroke_m": np.array([6e-4, 6e-4, 4e-4]), "blocked_force_N": np.zeros(3), "settling_s": np.zeros(3),
         "contact": np.array([False, False, False])}
    assert t.met(m).tolist() == [True, False, False]


def training(sd_rel=0.02):
    out = {}
    for w, d in rig.TRAINING_SAMPLES:
        p = rig.true_params(w, d)
        mean = np.array([getattr(p, n) for n in U.PARAMS])
        cov = np.diag((sd_rel * mean) ** 2)
        sid = rig.sample_id(w, d)
        out[sid] = U.ParameterUncertainty(sid, float(w), float(d), p, cov)
    return out


def test_outside_the_identified_samples_hull_the_design_is_refused():
    tr = training()
    fits, _ = surface_model(tr)
    space = default_space(tr, {"wt_pct": [5, 30], "gap_mm": [9], "voltage_V": [5]}, 3)
    with pytest.raises(DesignError, match=r"wt_pct=5, diameter_mm=30\) lies outside the convex hull of the "
                                          r"identified samples \(wt_pct 10-30"):
        nominal_params(fits, space)
    inside = nominal_params(fits, default_space(tr, {"gap_mm": [9], "voltage_V": [5]}, 3))
    assert inside["Em"][1, 1] == pytest.approx(rig.true_params(20, 45).Em, rel=1e-9)   # a node is reproduced


def test_design_search_is_identical_on_one_and_two_workers_and_gives_probabilities():
    tr = training()
    targets = Targets(stroke_mm=0.5, settling_ms=150.0, max_power_W=4.0)
    space = default_space(tr, {"gap_mm": [8], "voltage_V": [4, 9]}, 3)
    st = DesignSettings(n_draws=12, seed=5, max_candidates=4, t_step_s=0.3)
    one = design(tr, targets, space, st, ClusterSettings(workers=1, progress=False))
    two = design(tr, targets, space, st, ClusterSettings(workers=2, progress=False))
    assert space.size == 27
    for k in one.metrics:
        np.testing.assert_array_equal(one.metrics[k], two.metrics[k])
    assert one.candidates == two.candidates and one.front == two.front
    grid = [c for c in one.candidates if c["source"] == "grid"]
    assert 0 < len(grid) == int(one.feasible.sum()) < 27
    # every listed candidate (grid or refined) meets the spec nominally; the Monte-Carlo probabilities are
    # shares of 12 draws, given to the first 4 of the ranking
    for c in one.candidates:
        assert c["stroke_m"] >= 0.5e-3 and c["settling_s"] <= 0.15 and c["power_W"] <= 4.0
        assert 0.0 <= c["probability_linearised"] <= 1.0
    probs = [c["probability_mc"] for c in one.candidates if c["probability_mc"] is not None]
    assert len(probs) == min(4, len(one.candidates))
    assert all(abs(p * 12 - round(p * 12)) < 1e-9 for p in probs)
    # ranked by power (the default objective), those reaching the default --min-probability 0.95 first
    order = [(c["probability_linearised"] < 0.95, c["power_W"]) for c in one.candidates]
    assert order == sorted(order)


def test_bandwidth_of_a_butterworth_case_is_the_natural_frequency_and_k_t_is_the_force_gradient():
    G = kernel(P.a, P.D, P.kB, 0.009)
    m, K2 = 0.004, 40.0
    p = {"Em": np.array([P.Em]), "K1": np.zeros(1), "K2": np.array([K2]), "m": np.array([m]),
         "C": np.array([np.sqrt(2 * K2 * m)])}                          # damping ratio 1/sqrt(2)
    # negligible current (no magnetic stiffness) and inductance: |H| falls to 1/sqrt(2) at f_n exactly
    bw = E.bandwidth(G, 0.009, np.zeros(1), np.array([1e-6]), p, P.R, 1e-12)
    assert bw[0] == pytest.approx(np.sqrt(K2 / m) / (2 * np.pi), rel=5e-3)
    # with current: the magnetic force's gradient lowers the stiffness, and the coil's pole the bandwidth
    I = np.array([0.6])
    x, _ = E.static_point(G, 0.009, P.Em * I ** 2, np.zeros(1), np.array([K2]))
    h = 1e-7
    net = [P.Em * I[0] ** 2 * G(0.009 - z) - K2 * z for z in (x[0] - h, x[0] + h)]
    kt = -(net[1] - net[0]) / (2 * h)
    assert 0 < kt < K2
    p_c = dict(p, C=np.array([np.sqrt(2 * kt * m)]))
    bw_c = E.bandwidth(G, 0.009, x, I, p_c, P.R, 1e-12)
    assert bw_c[0] == pytest.approx(np.sqrt(kt / m) / (2 * np.pi), rel=5e-3)
    assert E.bandwidth(G, 0.009, x, I, p_c, P.R, P.L)[0] < bw_c[0]


def test_pull_in_current_is_the_largest_current_with_a_static_equilibrium():
    """I_pi^2 = max_x (K1 x^3 + K2 x) / (Em G(r0 - x)) (scalar maximisation by scipy); the static point exists
    just below it and not just above it."""
    from scipy.optimize import minimize_scalar
    r0 = 0.004
    G = kernel(P.a, P.D, P.kB, r0)
    ratio = lambda z: (P.K1 * z ** 3 + P.K2 * z) / (P.Em * G(r0 - z))     # noqa: E731
    best = max(minimize_scalar(lambda z: -ratio(z), bounds=(lo, hi), method="bounded", options={"xatol": 1e-12}).x
               for lo, hi in ((1e-9, r0 / 2), (r0 / 2, r0)))
    i_pi = np.sqrt(max(ratio(best), ratio(r0)))
    got = E.pull_in_current(G, r0, np.array([P.Em]), np.array([P.K1]), np.array([P.K2]))[0]
    assert got == pytest.approx(i_pi, rel=1e-4)
    I = np.array([0.99, 1.01]) * got
    _, pulled = E.static_point(G, r0, P.Em * I ** 2, np.full(2, P.K1), np.full(2, P.K2))
    assert pulled.tolist() == [False, True]
