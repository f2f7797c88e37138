"""Design advice (harness.analysis.design.advice and its use in run.design): refinement against hand-built
surfaces whose optimum is known analytically, the linearised probability against a hand formula and against
Monte Carlo, and properties of the ranking, the front and the whole search over random specs and objectives
(Hypothesis: a fast derandomized profile here, a deep one under -m deep)."""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from scipy.stats import norm

from harness.analysis.identification import generalize
from harness.analysis.identification import parameter_uncertainty as U
from harness.analysis.design import advice as A
from harness.analysis.design.run import (DesignSettings, default_space, design, linearised, monte_carlo,
                                         surface_model)
from harness.analysis.design.space import Axis, DesignError, DesignSpace, Targets
from harness.analysis.core.sweep import ClusterSettings
from harness.data import rig
from harness.sim.kernels import kernel

P = rig.true_params(20, 45)
COIL = {"a": P.a, "kB": P.kB, "R": P.R, "L": P.L}
C_EM = 0.0015                                    # hand-built surface: Em = C_EM * wt [N.m/A^2 per wt%]
TRIANGLE = ((10, 30), (30, 30), (10, 60))        # (wt%, D mm): a triangular hull, edge u + v = 1 in fit coordinates


def hand_nodes():
    """Em = C_EM * wt (linear in log wt: the Clough-Tocher surface reproduces it exactly), stiff constant
    spring (tiny strokes, no contact)."""
    return [(w, d, {"Em": C_EM * w, "K1": 1e6, "K2": 400.0, "C": 0.5, "m": 0.005}) for w, d in TRIANGLE]


def hand_space(D=35.0, gap=5.0):
    return DesignSpace(Axis("wt_pct", 10, 30, 5), Axis("diameter_mm", D, D, 1), Axis("gap_mm", gap, gap, 1),
                       Axis("voltage_V", 1, 12, 5))


ST = DesignSettings(t_step_s=0.3)


def test_refined_minimum_filler_is_the_analytic_one():
    """Minimise wt% with F_b = C_EM wt I^2 G(gap) >= F and V^2/R <= P_max: I = sqrt(P_max/R), wt* = F/(C_EM I^2 G)."""
    D, gap, p_max, w_star = 35.0, 5.0, 2.0, 17.0
    G = kernel(P.a, D / 1e3, P.kB, gap / 1e3)(gap / 1e3)
    F = C_EM * w_star * (p_max / P.R) * G
    start = (23.0, D, gap, math.sqrt(p_max * P.R))
    r = A.refine_task((hand_nodes(), COIL, Targets(blocked_force_N=F, max_power_W=p_max), hand_space(D, gap), start,
                       "filler", ST))
    assert r["moved"]
    assert r["design"][0] == pytest.approx(w_star, rel=1e-6)
    assert r["design"][3] == pytest.approx(math.sqrt(p_max * P.R), rel=1e-6)


def test_refined_minimum_power_sits_on_the_hull_edge():
    """Minimise power with F_b >= F at D = 35 mm: the largest Em, i.e. the largest wt% inside the triangle,
    wt_max = 10 * 3^(1 - v), v = ln(35/30)/ln 2 (edge u + v = 1); P* = R F / (C_EM wt_max G)."""
    D, gap = 35.0, 5.0
    G = kernel(P.a, D / 1e3, P.kB, gap / 1e3)(gap / 1e3)
    F = C_EM * 20 * 0.3 ** 2 * G
    w_max = 10 * 3 ** (1 - math.log(D / 30) / math.log(2))
    p_star = P.R * F / (C_EM * w_max * G)
    r = A.refine_task((hand_nodes(), COIL, Targets(blocked_force_N=F), hand_space(D, gap), (20.0, D, gap, 12.0),
                       "power", ST))
    assert r["design"][0] == pytest.approx(w_max, rel=1e-6)
    assert r["metrics"]["power_W"] == pytest.approx(p_star, rel=1e-6)
    fits = generalize.fit_surfaces(hand_nodes())
    generalize.predict(fits, *r["design"][:2])           # inside the hull (raises outside)


def test_hull_of_the_triangle_is_u_plus_v_at_most_one():
    """Fit coordinates u = ln(wt/10)/ln 3, v = ln(D/30)/ln 2: the triangle's slanted edge is u + v = 1."""
    hull = A.Hull.from_fits(generalize.fit_surfaces(hand_nodes()))
    for w, d in ((12.0, 35.0), (20.0, 45.0), (10.0, 60.0), (25.0, 31.0), (23.6, 35.0), (23.4, 35.0)):
        u, v = math.log(w / 10) / math.log(3), math.log(d / 30) / math.log(2)
        q = hull.scaled(w, d)[0]
        assert q == pytest.approx([u, v], abs=1e-12)
        assert (hull.slack(q).min() >= -1e-12) == (u + v <= 1 + 1e-12)
        assert hull.unscaled(q) == pytest.approx((w, d), rel=1e-12)


def test_an_unknown_objective_names_the_option():
    with pytest.raises(DesignError, match=r"^--minimise must be one of power, current, diameter, filler, got 'mass'$"):
        DesignSettings(objective="mass")


def test_robust_targets_move_each_bound_by_z_sigma():
    t = Targets(stroke_mm=1.0, settling_ms=100.0, max_power_W=3.0, blocked_force_N=0.5)
    sd = {"stroke_m": 0.02, "settling_s": 0.05}
    r = A.robust_targets(t, sd, 0.95)
    z = 1.6448536269514722                                   # Phi^-1(0.95)
    assert r.stroke_mm == pytest.approx(1.0 + z * 0.02, rel=1e-12)
    assert r.settling_ms == pytest.approx(100.0 / (1 + z * 0.05), rel=1e-12)
    assert r.blocked_force_N == 0.5 and r.max_power_W == 3.0          # no sd: the bound itself
    assert A.robust_targets(t, sd, 0.5) == t and A.robust_targets(t, sd, 0.0) == t


# ---------------------------------------------------------------- ranking and front (independent definitions)
def _dominated(i, obj, sc):
    return any((obj[j] <= obj[i] and sc[j] >= sc[i]) and (obj[j] < obj[i] or sc[j] > sc[i])
               for j in range(len(obj)))


@settings(max_examples=60, derandomize=True, database=None, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 6), st.integers(0, 6)), min_size=1, max_size=25))
def test_front_is_the_set_of_non_dominated_points(pts):
    obj = np.array([p[0] for p in pts], float)
    sc = np.array([p[1] for p in pts], float) / 6
    f = A.pareto_front(obj, sc)
    # every non-dominated point is represented (duplicates: one of them), nothing dominated is
    assert all(not _dominated(i, obj, sc) for i in f)
    nd = {(obj[i], sc[i]) for i in range(len(pts)) if not _dominated(i, obj, sc)}
    assert {(obj[i], sc[i]) for i in f} == nd and len(f) == len(nd)
    assert list(obj[f]) == sorted(obj[f])


@settings(max_examples=60, derandomize=True, database=None, deadline=None)
@given(st.lists(st.tuples(st.floats(0.1, 10), st.floats(0, 1), st.floats(-50, 50)), min_size=1, max_size=20),
       st.sampled_from(sorted(A.OBJECTIVES)))
def test_ranking_is_monotone_in_the_objective_then_the_probability(vals, objective):
    rows = [{"wt_pct": o, "diameter_mm": o, "power_W": o, "current_A": o, "probability_linearised": p, "margin_pct": m}
            for o, p, m in vals]
    r = A.rank(rows, objective)
    for a, b in zip(r, r[1:]):
        assert a["power_W"] < b["power_W"] or (a["power_W"] == b["power_W"]
                                               and a["probability_linearised"] >= b["probability_linearised"])


# ---------------------------------------------------------------- linearised probability
def _training(sd_rel):
    out = {}
    for w, d in rig.TRAINING_SAMPLES:
        p = rig.true_params(w, d)
        mean = np.array([getattr(p, n) for n in U.PARAMS])
        sid = rig.sample_id(w, d)
        out[sid] = U.ParameterUncertainty(sid, float(w), float(d), p, np.diag((sd_rel * mean) ** 2))
    return out


@pytest.fixture(scope="module")
def where():
    """An in-process Dask cluster shared by the tests of this module (the code path of --scheduler)."""
    from dask.distributed import LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as c:
        yield ClusterSettings(scheduler=c.scheduler_address, progress=False)


def _row(w, d, g, v):
    return {"source": "grid", "wt_pct": float(w), "diameter_mm": float(d), "gap_mm": float(g), "voltage_V": float(v)}


def _evaluate(tr, rows, where):
    """The rows' nominal metrics through the search itself (a one-design space per row)."""
    out = []
    for r in rows:
        sp = default_space(tr, {"wt_pct": [r["wt_pct"]], "diameter_mm": [r["diameter_mm"]], "gap_mm": [r["gap_mm"]],
                                "voltage_V": [r["voltage_V"]]}, 2)
        res = design(tr, Targets(max_power_W=1e9), sp, DesignSettings(refine=0, max_candidates=0, t_step_s=0.5),
                     where)
        out.append(dict(r, **{k: res.candidates[0][k] for k in res.candidates[0] if k not in r}))
    return out


def test_linearised_probability_of_the_blocked_force_at_a_node_is_the_hand_formula(where):
    """At a node the design's Em is the node's; F_b = Em I^2 G is proportional to Em, so sd(F_b)/F_b =
    sd(Em)/Em = 2 % and P(F_b >= (1 - 0.02) F_b) = Phi(1)."""
    tr = _training(0.02)
    _, coil = surface_model(tr)
    I = 6.0 / coil["R"]
    F = P.Em * I ** 2 * kernel(coil["a"], 0.045, coil["kB"], 0.008)(0.008)
    for frac, z in ((0.98, 1.0), (1.0, 0.0), (1.03, -1.5)):
        rows = [dict(_row(20, 45, 8, 6.0), current_A=I, power_W=6.0 * I, blocked_force_N=F, stroke_m=0.0, static_stroke_m=0.0,
                     settling_s=0.0, bandwidth_Hz=0.0, pull_in_current_A=1.0)]
        # contact allowed: the blocked force is the only uncertain target
        linearised(tr, Targets(blocked_force_N=frac * F, allow_contact=True), rows, coil, ST, (where, None))
        assert rows[0]["probability_linearised"] == pytest.approx(norm.cdf(z), abs=2e-3)


def test_linearised_probability_agrees_with_monte_carlo(where):
    """Three designs, each with a stroke spec 3 % below and 2 % above its nominal stroke (sd of the parameters
    2 %: P about 0.85-0.95 and 0.15-0.25): the delta method within 3 binomial standard errors + 0.03 of 300
    Monte-Carlo draws (measured: within 0.05; with the covariance doubled the linearised P misses by 0.14)."""
    tr = _training(0.02)
    _, coil = surface_model(tr)
    rows = _evaluate(tr, [_row(15, 37.5, 6, 5), _row(28, 55, 10, 9), _row(12, 33, 5, 4)], where)
    mc_st = DesignSettings(n_draws=300, seed=3, t_step_s=0.5)
    for r in rows:
        for frac in (0.97, 1.02):
            tg = Targets(stroke_mm=frac * r["stroke_m"] * 1e3)
            one = [dict(r)]
            linearised(tr, tg, one, coil, mc_st, (where, None))
            monte_carlo(tr, tg, one, coil, mc_st, (where, None))
            p_lin, p_mc, se = one[0]["probability_linearised"], one[0]["probability_mc"], one[0]["probability_mc_se"]
            assert 0.02 < p_mc < 0.98
            assert abs(p_lin - p_mc) <= 3 * max(se, 0.01) + 0.03, (r, frac, p_lin, p_mc)


@settings(max_examples=40, derandomize=True, database=None, deadline=None)
@given(st.integers(1, 3), st.integers(1, 4), st.integers(0, 2 ** 31 - 1), st.floats(-2, 2))
def test_linearised_probability_matches_the_explicit_gaussian_and_is_monotone_in_the_spec(T, nodes, seed, shift):
    """Random sensitivities: for one target P = Phi(mu/sigma) with sigma^2 = sum_i g_i^T C_i g_i written out;
    for every T, probabilities in [0, 1] and not larger for a tighter spec."""
    rng = np.random.default_rng(seed)
    n = 5
    keys = [k for k, _, _ in A.uncertain_targets(Targets(stroke_mm=1, blocked_force_N=1, settling_ms=1))][:T]
    nominal = {"stroke_m": rng.uniform(0.5e-3, 1.5e-3, n), "blocked_force_N": rng.uniform(0.5, 1.5, n),
               "settling_s": rng.uniform(0.5e-3, 1.5e-3, n), "current_A": np.zeros(n), "power_W": np.zeros(n)}
    d = {k: rng.normal(size=(n, 5)) * nominal[k][:, None] for k in nominal}
    dtheta = rng.uniform(0, 1, (n, 5, nodes))
    L = rng.normal(size=(nodes, 5, 5)) * 0.05
    cov = L @ np.transpose(L, (0, 2, 1))

    def spec(s):
        v = {"stroke_m": ("stroke_mm", 1.0 * (1 + 0.1 * s)), "blocked_force_N": ("blocked_force_N", 1.0 * (1 + 0.1 * s)),
             "settling_s": ("settling_ms", 1.0 * (1 - 0.1 * s))}
        return Targets(**{v[k][0]: v[k][1] for k in keys})

    p = A.linearised_probabilities(spec(shift), nominal, d, dtheta, cov)
    tighter = A.linearised_probabilities(spec(shift + 0.5), nominal, d, dtheta, cov)
    assert np.all((0 <= p) & (p <= 1)) and np.all(tighter <= p + 1e-12)
    if T == 1:
        k = keys[0]
        thr = spec(shift).stroke_mm / 1e3
        for j in range(n):
            var = 0.0
            for i in range(nodes):
                g = np.array([d[k][j, a] * dtheta[j, a, i] for a in range(5)])
                var += g @ cov[i] @ g
            assert p[j] == pytest.approx(norm.cdf((nominal[k][j] - thr) / math.sqrt(var)), abs=1e-9)


# ---------------------------------------------------------------- the whole search over random specs
TR = _training(0.01)
SPACE = default_space(TR, {"gap_mm": [4, 10], "voltage_V": [2, 12]}, 3)
SPECS = st.fixed_dictionaries({"stroke_mm": st.floats(0.2, 2.5)},
                              optional={"max_power_W": st.floats(1.0, 8.0), "settling_ms": st.floats(80, 300)})


def _check_search(where, spec, objective):
    targets = Targets(**spec)
    res = design(TR, targets, SPACE, DesignSettings(n_draws=4, max_candidates=3, refine=2, objective=objective,
                                                    t_step_s=0.4), where)
    key = A.OBJECTIVES[objective]
    fits, _ = surface_model(TR)
    grid = [c for c in res.candidates if c["source"] == "grid"]
    for c in res.candidates:                    # feasible (thresholds written out), inside the space and the hull
        assert c["stroke_m"] * 1e3 >= spec["stroke_mm"] and not c["contact"]
        assert c["power_W"] <= spec.get("max_power_W", math.inf)
        assert c["settling_s"] * 1e3 <= spec.get("settling_ms", math.inf)
        for a in SPACE.axes:
            assert a.lo - 1e-9 <= c[a.name] <= a.hi + 1e-9
        generalize.predict(fits, c["wt_pct"], c["diameter_mm"])
        assert c["probability_linearised"] is None or 0 <= c["probability_linearised"] <= 1
    # ranked: the designs reaching --min-probability (0.95) first, each group by ascending objective
    order = [(not (c["probability_linearised"] is not None and c["probability_linearised"] >= 0.95), c[key])
             for c in res.candidates]
    assert order == sorted(order)
    if grid:
        # every refined design is no worse than its grid start (a feasible grid candidate); the first start
        # is the best grid design of its group (reaching --min-probability or not), so the refined one from
        # it is no worse than that
        by_design = {(c["wt_pct"], c["diameter_mm"], c["gap_mm"], c["voltage_V"]): c for c in grid}
        for c in res.candidates:
            if c["source"] == "refined":
                s = by_design[c["start_design"]]
                assert c[key] <= s[key] + 1e-12
    else:
        assert not res.candidates and res.nearest and all(r["margin_pct"] < 0 for r in res.nearest)
    # tighter stroke spec: no design's linearised probability grows
    rows = [dict(c) for c in res.candidates[:6]]
    if rows:
        tighter = Targets(**dict(spec, stroke_mm=spec["stroke_mm"] * 1.05))
        _, coil = surface_model(TR)
        linearised(TR, tighter, rows, coil, DesignSettings(t_step_s=0.4), (where, None))
        for a, b in zip(res.candidates, rows):
            if a["probability_linearised"] is not None and b["probability_linearised"] is not None:
                assert b["probability_linearised"] <= a["probability_linearised"] + 1e-12


@settings(max_examples=4, derandomize=True, database=None, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(SPECS, st.sampled_from(sorted(A.OBJECTIVES)))
# found by the deep profile: nothing feasible, and designs in contact (stroke and settling met) were listed
# as the nearest with a positive margin
@example(spec={"stroke_mm": 2.0, "settling_ms": 80.0}, objective="current")
# found by the deep profile: the best grid design by wt% misses --min-probability, so the refinement starts
# from the best design reaching it; the test's invariant was too strong (refined <= best grid design overall)
@example(spec={"stroke_mm": 1.0, "settling_ms": 80.0}, objective="filler")
def test_search_invariants_fast(where, spec, objective):
    _check_search(where, spec, objective)


@pytest.mark.deep
@settings(max_examples=60, derandomize=False, database=None, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(SPECS, st.sampled_from(sorted(A.OBJECTIVES)))
def test_search_invariants_deep(where, spec, objective):
    _check_search(where, spec, objective)
