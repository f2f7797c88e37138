"""The diagnosis's parametrization of the catalogue (harness.analysis.diagnosis.candidates)."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from fmu_src.specs import EFFECTS
from harness.analysis.diagnosis.candidates import (BASE_KEYS, CANDIDATES, EVIDENCE_POINTS_TO, SHARED_DEFS,
                                                   base_bounds, base_vector, make_params, off_init, shared_defs)
from harness.data import rig

GEOM = SimpleNamespace(a=0.02, D=0.045, kB=0.29)


def test_catalogue_is_covered():
    """Every effect of fmu_src.effects is a candidate, with its own shared parameters; every feature points
    to catalogue effects only."""
    assert CANDIDATES == tuple(EFFECTS)
    for name, defs in SHARED_DEFS.items():
        assert defs and all(d.effect == name for d in defs)
        assert all(d.lo < d.hi and d.fd > 0 and d.lo <= d.init <= d.hi for d in defs)
    for text in EVIDENCE_POINTS_TO.values():
        assert any(e in text for e in EFFECTS)


def test_base_vector_round_trip():
    """base_vector(make_params(b)) == b: logs of R, L, Em, K1, K2, zeta = C/(2 sqrt(K2 m)), m."""
    R, L, Em, K1, K2, zeta, m = 12.0, 0.03, 2e-4, 3e6, 150.0, 0.4, 2e-3
    b = np.log([R, L, Em, K1, K2, zeta, m])
    p = make_params(GEOM, b, {})
    assert p.C == pytest.approx(2 * zeta * math.sqrt(K2 * m), rel=1e-14)     # independent formula
    assert (p.a, p.D, p.kB) == (GEOM.a, GEOM.D, GEOM.kB)
    assert np.allclose(base_vector(p), b, rtol=0, atol=1e-12)
    assert len(BASE_KEYS) == b.size


def test_effects_off_at_the_start_and_mapped_when_on():
    b = np.log([12.0, 0.03, 2e-4, 3e6, 150.0, 0.4, 2e-3])
    every = tuple(EFFECTS)
    p0 = make_params(GEOM, b, off_init(every))
    assert all(getattr(p0, e.switch) == 0.0 for e in EFFECTS.values())
    sh = {d.key: (d.init if d.log else 0.5 * (d.lo + min(d.hi, 1.0))) for d in shared_defs(every)}
    p = make_params(GEOM, b, sh)
    assert all(getattr(p, e.switch) > 0.0 for e in EFFECTS.values())
    assert p.Kc == pytest.approx(sh["creep_ratio"] * 150.0)                 # Kc = (Kc/K2) K2
    assert p.K5 == pytest.approx(sh["edge_ratio"] * 3e6 / GEOM.D ** 2)      # K5 = (K5 D^2/K1) K1 / D^2
    assert p.tau_th == pytest.approx(5.0) and p.tau_c == pytest.approx(1.0)  # log-fitted time constants
    p.validated()


def test_base_bounds():
    b0 = base_vector(rig.true_params(20, 45))
    lo, hi = base_bounds(b0)
    assert np.all(lo <= b0) and np.all(b0 <= hi)
    K2 = math.exp(b0[4])
    fn_hi, fn_lo = (math.sqrt(K2 / math.exp(v)) / (2 * math.pi) for v in (lo[6], hi[6]))
    assert fn_hi == pytest.approx(100.0) and fn_lo == pytest.approx(1.0)    # m for f_n in 1-100 Hz
    assert math.exp(lo[5]) == pytest.approx(0.02) and math.exp(hi[5]) == pytest.approx(2.0)


def test_edge_starts_balance_the_static_points_with_the_quintic_spring():
    """``extra_starts("edge_stiffening")``: at each ratio e of EDGE_RATIO_STARTS, K1 and K2 balance the magnetic force
    at T3's and T5's static points with K5 = e K1 / D^2. Against a sample built by hand: true springs (K1, K2, K5 of
    ratio e), static deflections found by brentq on K1 x^3 + K2 x + K5 x^5 = Em I^2 G(r0 - x) with the tabulated
    kernel's quadrature (fmu_src.field.force_kernel), records holding those deflections; Em, the coil and C are kept."""
    from scipy.optimize import brentq

    from fmu_src.field import force_kernel
    from harness.analysis.diagnosis.candidates import EDGE_RATIO_STARTS, extra_starts
    D, a, kB, r0 = 0.06, 0.015, 0.3, 0.008
    Em, K1, K2, m, C = 0.05, 4e5, 30.0, 0.01, 0.6
    e = EDGE_RATIO_STARTS[1]
    K5 = e * K1 / D ** 2
    tests = {}
    for name, I in (("T3", 0.8), ("T5", 1.5)):
        x = brentq(lambda x: K1 * x ** 3 + K2 * x + K5 * x ** 5 - Em * I * I * force_kernel(r0 - x, a, D, kB)[0],
                   0.0, 0.999 * r0)
        n = 400
        tests[name] = SimpleNamespace(blocked=False, k_on=40, r0=r0, y=np.r_[np.zeros(40), np.full(n - 40, x)],
                                      I=np.r_[np.zeros(40), np.full(n - 40, I)])
    sd = SimpleNamespace(a=a, D=D, kB=kB, tests=tests)
    zeta = C / (2 * math.sqrt(3 * K2 * m))
    b = np.log([15.0, 0.1, Em, 3 * K1, 3 * K2, zeta, m])       # a reference with the wrong springs
    starts = extra_starts("edge_stiffening", [sd], {0: b}, {"ln_a_ratio": 0.0})
    assert [sh["edge_ratio"] for _, sh in starts] == list(EDGE_RATIO_STARTS)
    assert all(sh["ln_a_ratio"] == 0.0 for _, sh in starts)     # the reference's nuisance values carried
    got = starts[1][0][0]
    assert math.exp(got[3]) == pytest.approx(K1, rel=2e-3) and math.exp(got[4]) == pytest.approx(K2, rel=2e-3)
    assert np.allclose(got[[0, 1, 2, 6]], b[[0, 1, 2, 6]])     # R, L, Em, m kept
    p = make_params(sd, got, starts[1][1])
    assert p.C == pytest.approx(C, rel=1e-9) and p.K5 == pytest.approx(K5, rel=2e-3)    # the same damping
    assert extra_starts("coil_heating", [sd], {0: b}, {}) == []
    sd.tests.pop("T5")                                          # no second static point: no start moves a sample
    assert extra_starts("edge_stiffening", [sd], {0: b}, {}) == []


def test_saturation_starts_keep_t8s_force_and_balance_the_static_points():
    """``extra_starts("filler_saturation")``: at each ksat of SATURATION_STARTS, Em is raised so that T8's blocked force
    stays that of the reference (which read T8 without saturation: Em_true / (1 + ksat (kB I8)^2)), and K1, K2 balance
    the saturated force at T3's and T5's static points. Against a sample built by hand (static deflections by brentq
    on K1 x^3 + K2 x = Em I^2 G(r0 - x) / (1 + ksat (kB I)^2) with the kernel's quadrature)."""
    from scipy.optimize import brentq

    from fmu_src.field import force_kernel
    from harness.analysis.diagnosis.candidates import SATURATION_STARTS, extra_starts
    D, a, kB, r0 = 0.05, 0.015, 0.3, 0.008
    Em, K1, K2, m, C = 0.02, 4e5, 30.0, 0.01, 0.6
    ksat = SATURATION_STARTS[1]
    I8 = 1.5
    tests = {"T8": SimpleNamespace(blocked=True, k_on=40, r0=0.002, y=np.zeros(400),
                                   I=np.r_[np.zeros(40), np.full(360, I8)])}
    for name, I in (("T3", 0.8), ("T5", 1.5)):
        x = brentq(lambda x: K1 * x ** 3 + K2 * x - Em * I * I * force_kernel(r0 - x, a, D, kB)[0]
                   / (1 + ksat * (kB * I) ** 2), 0.0, 0.999 * r0)
        tests[name] = SimpleNamespace(blocked=False, k_on=40, r0=r0, y=np.r_[np.zeros(40), np.full(360, x)],
                                      I=np.r_[np.zeros(40), np.full(360, I)])
    sd = SimpleNamespace(a=a, D=D, kB=kB, tests=tests)
    Em_ref = Em / (1 + ksat * (kB * I8) ** 2)
    b = np.log([15.0, 0.1, Em_ref, 2 * K1, 2 * K2, C / (2 * math.sqrt(2 * K2 * m)), m])
    starts = extra_starts("filler_saturation", [sd], {0: b}, {})
    ks = [sh["ksat"] for _, sh in starts]
    assert ks == list(SATURATION_STARTS[:2]), ks    # at 10 / T^2 the balance needs a negative K1: no start
    got, sh = starts[1][0][0], starts[1][1]
    assert math.exp(got[2]) == pytest.approx(Em, rel=1e-9)
    assert math.exp(got[3]) == pytest.approx(K1, rel=2e-3) and math.exp(got[4]) == pytest.approx(K2, rel=2e-3)
    assert make_params(sd, got, sh).C == pytest.approx(C, rel=1e-9)


def test_heating_starts_give_a_cold_resistance_whose_mean_heating_is_the_references():
    """``extra_starts("coil_heating")``: at each Rth of HEATING_STARTS (tau_th at its start value), R is the cold
    resistance R0 such that the hot resistance R0 (1 + 0.0039 dT), averaged over the step records T3, T5, T8 after their
    steps, is about the reference's R (what a fit without heating finds). Checked by integrating the winding's own
    equation dT' = (Rth V^2 / R(T) - dT) / tau_th (solve_ivp, voltage V from the step on) at the start's R0: the mean
    hot resistance is the reference's to a tenth of the correction (first order in the heating); the other base
    parameters and the nuisance values are kept."""
    from scipy.integrate import solve_ivp

    from fmu_src.effects import ALPHA_CU
    from harness.analysis.diagnosis.candidates import HEATING_STARTS, extra_starts
    R_ref = 12.0
    recs = {"T3": (5.0, 3.0, 500), "T5": (7.0, 4.5, 500), "T8": (6.0, 2.0, 300)}     # V [V], record after step [s], k_on
    tests = {}
    for name, (V, T, k_on) in recs.items():
        t = np.r_[np.linspace(-0.5, 0.0, k_on, endpoint=False), np.linspace(0.0, T, 2000)]
        tests[name] = SimpleNamespace(blocked=name == "T8", k_on=k_on, t=t, V_on=V,
                                      y=np.zeros(t.size), I=np.zeros(t.size))
    sd = SimpleNamespace(a=0.015, D=0.05, kB=0.3, tests=tests)
    b = np.log([R_ref, 0.1, 0.02, 4e5, 30.0, 0.5, 0.01])
    starts = extra_starts("coil_heating", [sd], {0: b}, {"ln_a_ratio": 0.01})
    assert [sh["Rth"] for _, sh in starts] == list(HEATING_STARTS)
    for base, sh in starts:
        got = base[0]
        assert sh["ln_a_ratio"] == 0.01 and np.allclose(got[1:], b[1:])
        R0, Rth, tau = math.exp(got[0]), sh["Rth"], math.exp(sh["tau_th"])
        assert R0 < R_ref
        means = []
        for name, (V, T, _) in recs.items():
            sol = solve_ivp(lambda _t, dT: (Rth * V ** 2 / (R0 * (1 + ALPHA_CU * dT)) - dT) / tau, (0.0, T), [0.0],
                            dense_output=True, rtol=1e-9, atol=1e-12)
            tt = np.linspace(0.0, T, 4001)
            means.append(float(np.mean(R0 * (1 + ALPHA_CU * sol.sol(tt)[0]))))
        hot = float(np.mean(means))
        assert R_ref - R0 > 0.01 * R_ref                                  # the case heats: 1-5 % of R
        assert abs(hot - R_ref) < 0.1 * (R_ref - R0), (Rth, R0, hot)    # within a tenth of the correction
    sd.tests = {}                                                     # no step record: no start
    assert extra_starts("coil_heating", [sd], {0: b}, {}) == []
