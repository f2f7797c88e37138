"""fmu_src.statics (static inverse, equilibria, pull-in) against an independent force balance: the force
kernel of tests/independent/physics.py (its own quadrature of the loop field) and the paper's Duffing
spring, solved with scipy's brentq / a fine grid here."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar

from fmu_src.model import ActuatorModel
from fmu_src.specs import Params
from fmu_src.statics import Statics

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "independent"))
from physics import kernel_G  # noqa: E402  (independent: imports nothing of the project)


def G(p, r):
    return kernel_G(r, p.a, p.D, p.kB)


def spring(p, x):
    return (p.K1 * x * x + p.K2) * x


def v_hold_indep(p, x, ksat=0.0):
    """Voltage holding x from Em*I^2*G/(1 + ksat*(kB*I)^2) = K(x): I^2 = K/(Em*G - ksat*kB^2*K), V = R*I."""
    K = spring(p, x)
    return p.R * math.sqrt(K / (p.Em * G(p, p.r0 - x) - ksat * p.kB ** 2 * K))


@pytest.mark.parametrize("x_mm", [0.2, 1.0, 2.5, 4.0, 5.0])
def test_static_inverse_is_the_independent_equilibrium(x_mm):
    p = Params()
    x = x_mm * 1e-3
    V = Statics(p).voltage_for(x)
    assert V == pytest.approx(v_hold_indep(p, x), rel=2e-5)
    # forward: brentq on the independent force balance at that voltage finds x again (stable branch)
    I = V / p.R
    x_back = brentq(lambda z: p.Em * I * I * G(p, p.r0 - z) - spring(p, z), 0.0, x + 0.2e-3)   # below the unstable root
    assert x_back == pytest.approx(x, abs=2e-8)


def test_forward_map_matches_brentq_equilibria():
    p = Params()
    s = Statics(p)
    for V in (5.0, 10.0, 15.0, 19.0):
        I = V / p.R
        f = lambda z: p.Em * I * I * G(p, p.r0 - z) - spring(p, z)   # noqa: E731
        zs = np.linspace(0, p.r0, 400)
        k = next(i for i, z in enumerate(zs) if f(z) < 0)   # first sign change: the stable equilibrium
        assert s.displacement_for(V) == pytest.approx(brentq(f, zs[k - 1], zs[k]), abs=2e-8)
    assert s.displacement_for(1.05 * s.v_pull_in) == p.r0   # beyond pull-in: contact


def test_pull_in_is_the_fold_of_the_independent_static_curve():
    p = Params()
    s = Statics(p)
    res = minimize_scalar(lambda x: -v_hold_indep(p, x), bounds=(1e-4, p.r0 - 1e-4), method="bounded",
                          options={"xatol": 1e-9})
    assert s.x_pull_in == pytest.approx(res.x, abs=5e-6)
    assert s.v_pull_in == pytest.approx(-res.fun, rel=1e-5)
    assert Statics(p.with_(r0=0.003)).x_pull_in == 0.003   # small gap: the Duffing spring wins up to the face


def test_effects_in_the_static_inverse():
    p = Params()
    x = 2e-3
    sat = p.with_(ksat=3.0)
    assert Statics(sat).voltage_for(x) == pytest.approx(v_hold_indep(p, x, ksat=3.0), rel=2e-5)
    heat = p.with_(Rth=8.0, tau_th=4.0)   # steady winding: dT = Rth*I^2*R*(1 + a*dT), V = R*(1 + a*dT)*I
    I = v_hold_indep(p, x) / p.R
    dT = 8.0 * I * I * p.R / (1.0 - 0.0039 * 8.0 * I * I * p.R)
    assert Statics(heat).voltage_for(x) == pytest.approx(p.R * (1 + 0.0039 * dT) * I, rel=2e-5)


def test_holding_the_static_inverse_settles_at_the_target():
    p = Params()
    x = 1.5e-3
    m = ActuatorModel(p)
    m.reset(0.0)
    m.advance(2.0, Statics(p).voltage_for(x))
    assert m.outputs()["x"] == pytest.approx(x, abs=1e-8)


def test_thermal_runaway_limits_the_holdable_range():
    p = Params().with_(Rth=10.0, tau_th=4.0)   # runaway where alpha*Rth*I^2*R = 1: I = 1.307 A (< 1.366 A at pull-in)
    s = Statics(p)
    I_run = 1.0 / math.sqrt(0.0039 * 10.0 * p.R)
    x_run = brentq(lambda x: v_hold_indep(Params(), x) / p.R - I_run, 1e-4, s.x_pull_in)
    assert s.x_holdable == pytest.approx(x_run, abs=1e-6) and s.x_holdable < s.x_pull_in
    xs, V = s.table(50)
    assert np.all(np.diff(V) > 0) and xs[-1] <= s.x_holdable


def test_every_effect_state_is_at_rest_in_the_steady_state():
    """The steady-state rules come from the specs (StateSpec.steady), not from effect names: with every
    effect on, the steady state has every effect state's rate zero and the readings equal to x and F."""
    from fmu_src.model import FREE
    from fmu_src.specs import EFFECTS, StateSpec
    p = Params().with_(Rth=8.0, tau_th=4.0, ksat=3.0, Kc=20.0, tau_c=2.0, K5=1e9, lam=5.0, tau_s=0.002)
    s = Statics(p)
    I, x = 0.6, 1.2e-3
    y = s.state(I, x)
    rates = s.dyn.rhs(y, s.voltage(I, x), FREE)
    assert abs(rates[0]) < 1e-9 * I                          # the steady voltage holds I
    names = s.names
    assert set(names[3:]) == {st.name for e in EFFECTS.values() for st in e.state_specs}
    for i, n in enumerate(names[3:], start=3):
        assert abs(rates[i]) <= 1e-9 * max(1.0, abs(y[i])) / 1e-3, (n, rates[i])
    assert y[names.index("x_sensor")] == x and y[names.index("xc")] == x
    assert y[names.index("F_sensor")] == pytest.approx(s.dyn.force(y, FREE), rel=1e-12)
    assert y[names.index("dT")] > 0
    with pytest.raises(ValueError, match="steady must be one of"):
        StateSpec("z", "m", "a state with an unknown rule", steady="relaxed")
