"""Candidate effects (fmu_src.effects) against independent hand-computed cases and references.

References are written here from the effect definitions, not taken from fmu_src:
* static equilibria by brentq with the force kernel by quadrature (fmu_src.field.force_kernel);
* closed forms (RL exponentials, steady coil temperature from the quadratic, saturation factor);
* an independent right-hand side of the free-mode ODE with every effect, solved by scipy DOP853;
* the flux balance d(L(x) I)/dt = V - R I integrated by the trapezoid rule on a fine grid;
* an exact discrete first-order filter of the sampled x (and F) for the sensor lag.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from fmu_src.field import force_kernel
from fmu_src.model import ActuatorModel, Dynamics, EffectDynamics, simulate
from fmu_src.specs import EFFECT_SPECS, EFFECTS, Params, active_effects, validate
from fmu_src import effects as fx
from harness.data import protocol
from harness.sim import virtual_rig

P = Params()
V0 = 0.23 / P.kB * P.R       # the FMU's start voltage: 0.23 T at the coil face, I = 0.793 A
ALPHA = 0.0039               # copper, 1/K (the brief's value, not imported)

# one switched-on parameter set per effect (moderate values; time constants short where a steady state is needed)
ON = {
    "coil_heating": dict(Rth=8.0, tau_th=0.05),
    "filler_saturation": dict(ksat=3.0),
    "viscoelastic_creep": dict(Kc=15.0, tau_c=0.08),
    "edge_stiffening": dict(K5=2e11),
    "motional_emf": dict(lam=0.3),
    "sensor_lag": dict(tau_s=0.004),
}


def G(r, p=P):
    return float(force_kernel(r, p.a, p.D, p.kB)[0])


def step_grid(T, dt=1e-3):
    return np.round(np.arange(0.0, T + 0.5 * dt, dt), 12)


# ----------------------------------------------------------------------------------------- catalogue, switching
def test_catalogue_names_and_parameters():
    assert list(EFFECTS) == ["coil_heating", "filler_saturation", "viscoelastic_creep", "edge_stiffening",
                                "motional_emf", "sensor_lag"]
    units = {s.name: s.unit for s in EFFECT_SPECS}
    assert units == {"Rth": "K/W", "tau_th": "s", "ksat": "1/T2", "Kc": "N/m", "tau_c": "s", "K5": "N/m5",
                     "lam": "1", "tau_s": "s"}
    for s in EFFECT_SPECS:
        assert s.default == 0.0 and getattr(P, s.name) == 0.0 and s.description
        assert not s.positive and s.nonnegative
    assert active_effects(P) == ()
    for name, kw in ON.items():
        assert active_effects(P.with_(**kw)) == (name,)


def test_all_off_runs_the_plain_dynamics_bit_identically():
    t = step_grid(0.4)
    V = V0 * (1.0 + 0.4 * np.sin(2 * np.pi * 7.0 * t)) * (t < 0.3)
    # time constants alone do not switch anything on
    only_taus = P.with_(tau_th=4.0, tau_c=1.0)
    for p in (P, P.with_(r0=0.0045), P.with_(r0=0.002, blocked=True)):
        assert type(ActuatorModel(p).dyn) is Dynamics
        assert type(ActuatorModel(only_taus.with_(r0=p.r0, blocked=p.blocked)).dyn) is Dynamics
        a = simulate(p, t, V)
        b = simulate(p, t, V, dynamics_cls=Dynamics)
        c = simulate(only_taus.with_(r0=p.r0, blocked=p.blocked), t, V)
        for k in a:
            assert np.array_equal(a[k], b[k]) and np.array_equal(a[k], c[k]), k
        assert np.array_equal(a["x_sensor"], a["x"]) and np.array_equal(a["F_sensor"], a["F"])
    # the plain Dynamics refuses effect parameters instead of ignoring them
    with pytest.raises(ValueError, match="EffectDynamics"):
        Dynamics(P.with_(ksat=1.0))
    assert type(ActuatorModel(P.with_(ksat=1.0)).dyn) is EffectDynamics


@pytest.mark.parametrize("kw,bad", [({"Rth": -1.0}, "Rth"), ({"lam": float("nan")}, "lam"),
                                    ({"Rth": 8.0}, "tau_th"), ({"Kc": 5.0, "tau_c": 0.0}, "tau_c"),
                                    ({"tau_s": float("inf")}, "tau_s")])
def test_bad_effect_parameters_are_named(kw, bad):
    with pytest.raises(ValueError, match=rf"parameter {bad}\b"):
        validate(kw)
    with pytest.raises(ValueError, match=rf"parameter {bad}\b"):
        ActuatorModel(P.with_(**kw))


# ----------------------------------------------------------------------------------------- physics core functions
# fmu_src.effects' core functions (used by EffectDynamics and by harness.analysis.diagnose's batch integrator) against
# numbers computed by hand from the effect definitions, on floats and on numpy arrays.
def _vec_equals_scalars(f, *args):
    """f on (n,) arrays (scalar args broadcast) equals f on each element as Python floats; returns f(arrays)."""
    n = max(np.size(a) for a in args if isinstance(a, np.ndarray))
    vec = f(*args)
    for i in range(n):
        one = f(*[float(a[i]) if isinstance(a, np.ndarray) else a for a in args])
        for v, o in zip(vec if isinstance(vec, tuple) else (vec,), one if isinstance(one, tuple) else (one,)):
            assert isinstance(o, float) and np.shape(v) == (n,), (f.__name__, type(o), np.shape(v))
            assert v[i] == pytest.approx(o, rel=1e-14, abs=1e-300), (f.__name__, i, v[i], o)
    return vec


RNG = np.random.default_rng(11)


def _u(lo, hi, n=7):
    return RNG.uniform(lo, hi, n)


def test_core_resistance():
    assert fx.resistance(15.0, 100.0) == pytest.approx(15.0 * 1.39, rel=1e-15)     # +39 % at 100 K (copper)
    assert fx.resistance(15.0, 0.0) == 15.0
    R, dT = _u(5, 20), _u(0, 120)
    got = _vec_equals_scalars(fx.resistance, R, dT)
    assert np.allclose(got, R + R * ALPHA * dT, rtol=1e-14, atol=0)


def test_core_inductance_terms():
    # a = 30 mm, r = 40 mm: a^2 + r^2 = (50 mm)^2, so a^3/(a^2 + r^2)^1.5 = 27/125 = 0.216
    Lx, dLdx = fx.inductance_terms(0.1, 0.5, 0.03, 0.04)
    assert Lx == pytest.approx(0.1 * (1 + 0.5 * 0.216), rel=1e-14)                  # 0.1108 H
    assert dLdx == pytest.approx(3 * 0.1 * 0.5 * 2.7e-5 * 0.04 / 0.05 ** 5, rel=1e-14)   # 0.5184 H/m
    assert fx.inductance_gradient(0.1, 0.5, 0.03, 0.04) == dLdx
    assert fx.inductance_terms(0.12, 0.0, 0.015, 0.004) == (0.12, 0.0)
    # dL/dx = -dL/dr of the definition L*(1 + lam*(a^2/(a^2 + r^2))^1.5), by central differences
    L, lam, a = 0.12, 0.3, 0.015
    Ldef = lambda r: L * (1 + lam * (a * a / (a * a + r * r)) ** 1.5)
    r, e = _u(-0.002, 0.03), 1e-7
    got = _vec_equals_scalars(fx.inductance_terms, L, lam, a, r)
    assert np.allclose(got[0], Ldef(r), rtol=1e-14, atol=0)
    assert np.allclose(got[1], -(Ldef(r + e) - Ldef(r - e)) / (2 * e), rtol=1e-6, atol=1e-9)


def test_core_current_rate():
    assert fx.current_rate(12.0, 0.5, 15.0, 0.12) == pytest.approx((12.0 - 7.5) / 0.12, rel=1e-15)   # 37.5 A/s
    # motional EMF with the numbers of test_core_inductance_terms: L(x) = 0.1108 H, dL/dx = 0.5184 H/m, v = 0.2 m/s
    got = fx.current_rate(12.0, 0.5, 15.0, 0.1, 0.5, 0.03, 0.04, 0.2)
    assert got == pytest.approx((12.0 - 7.5 - 0.5 * 0.2 * 0.5184) / 0.1108, rel=1e-13)
    assert fx.current_rate(12.0, 0.5, 15.0, 0.1, 0.0, 0.03, 0.04, 0.2) == pytest.approx(37.5 * 0.12 / 0.1, rel=1e-15)
    # arrays; the flux balance d(L(x) I)/dt = L(x) I' + I dL/dx v = V - R I, L(x) from its definition
    V, I, R, L, lam, a, r, v = _u(0, 15), _u(0, 1), _u(10, 20), _u(0.05, 0.2), _u(0, 0.5), 0.015, _u(0, 0.02), \
        _u(-0.5, 0.5)
    Ldef = lambda rr: L * (1 + lam * (a * a / (a * a + rr * rr)) ** 1.5)
    dLdx = -(Ldef(r + 1e-7) - Ldef(r - 1e-7)) / 2e-7
    dI = _vec_equals_scalars(fx.current_rate, V, I, R, L, lam, a, r, v)
    assert np.allclose(Ldef(r) * dI + I * dLdx * v, V - R * I, rtol=1e-7, atol=1e-9)
    assert np.allclose(_vec_equals_scalars(fx.current_rate, V, I, R, L), (V - R * I) / L, rtol=1e-14, atol=0)


def test_core_magnetic_force():
    assert fx.magnetic_force(0.1, 2.0, 3.0) == pytest.approx(1.2, rel=1e-15)          # Em I^2 G
    # kB I = 0.5 T, B_sat^2 = 1/3 T^2: factor 1/(1 + 0.75)
    assert fx.magnetic_force(0.1, 2.0, 3.0, 3.0, 0.25) == pytest.approx(1.2 / 1.75, rel=1e-15)
    assert fx.magnetic_force(0.1, -2.0, 3.0, 3.0, 0.25) == pytest.approx(1.2 / 1.75, rel=1e-15)   # even in I
    Em, I, Gr, ksat, kB = _u(0.01, 0.2), _u(-1, 1), _u(0.1, 10), _u(0, 5), 0.29
    got = _vec_equals_scalars(fx.magnetic_force, Em, I, Gr, ksat, kB)
    Bsat = 1 / np.sqrt(ksat)
    assert np.allclose(got, Em * I ** 2 * Gr / (1 + (kB * I / Bsat) ** 2), rtol=1e-14, atol=0)
    assert np.allclose(_vec_equals_scalars(fx.magnetic_force, Em, I, Gr), Em * I ** 2 * Gr, rtol=1e-15, atol=0)


def test_core_spring_forces_and_stiffness():
    # x = 2 mm: Duffing (4e5*4e-6 + 30)*0.002 = 0.0632 N; K5 x^5 = 1e12*3.2e-14 = 0.032 N;
    # creep branch 20 N/m * (2 - 0.5) mm = 0.03 N
    x, K1, K2, K5, Kc, xc = 0.002, 4e5, 30.0, 1e12, 20.0, 0.0005
    assert fx.effect_spring_force(x) == 0.0
    assert fx.effect_spring_force(x, K5) == pytest.approx(0.032, rel=1e-14)
    assert fx.effect_spring_force(x, None, Kc, xc) == pytest.approx(0.03, rel=1e-14)
    assert fx.effect_spring_force(x, K5, Kc, xc) == pytest.approx(0.062, rel=1e-14)
    assert fx.restoring_force(x, K1, K2) == pytest.approx(0.0632, rel=1e-14)
    assert fx.restoring_force(x, K1, K2, K5, Kc, xc) == pytest.approx(0.1252, rel=1e-14)
    # tangent: 3*4e5*4e-6 + 30 = 34.8; + 5*1e12*1.6e-11 = 80; + Kc = 20
    assert fx.tangent_stiffness(x, K1, K2) == pytest.approx(34.8, rel=1e-14)
    assert fx.tangent_stiffness(x, K1, K2, K5) == pytest.approx(114.8, rel=1e-14)
    assert fx.tangent_stiffness(x, K1, K2, K5, Kc) == pytest.approx(134.8, rel=1e-14)
    xs, K5s, Kcs, xcs = _u(-0.01, 0.01), _u(0, 1e12), _u(0, 30), _u(-0.005, 0.005)
    hand = lambda z: K1 * z ** 3 + K2 * z + K5s * z ** 5 + Kcs * (z - xcs)
    assert np.allclose(_vec_equals_scalars(fx.effect_spring_force, xs, K5s, Kcs, xcs),
                       K5s * xs ** 5 + Kcs * (xs - xcs), rtol=1e-13, atol=1e-18)
    assert np.allclose(_vec_equals_scalars(fx.restoring_force, xs, K1, K2, K5s, Kcs, xcs), hand(xs),
                       rtol=1e-13, atol=1e-18)
    kt = _vec_equals_scalars(fx.tangent_stiffness, xs, K1, K2, K5s, Kcs)
    assert np.allclose(kt, (hand(xs + 1e-8) - hand(xs - 1e-8)) / 2e-8, rtol=1e-6)   # d/dx, dashpot held


def test_core_acceleration_and_contact_force():
    x, v, F, K1, K2, C, m, K5, Kc, xc = 0.002, 0.1, 0.5, 4e5, 30.0, 0.2, 0.004, 1e12, 20.0, 0.0005
    # (0.5 - 0.2*0.1 - 0.0632)/0.004 = 104.2; with the effects' 0.062 N more: (0.3548)/0.004 = 88.7
    assert fx.diaphragm_acceleration(x, v, F, K1, K2, C, m) == pytest.approx(104.2, rel=1e-13)
    assert fx.diaphragm_acceleration(x, v, F, K1, K2, C, m, fx.effect_spring_force(x, K5, Kc, xc)) == pytest.approx(88.7, rel=1e-13)
    # on the coil face (r0 = 2 mm): 0.5 - 0.0632 (paper) - 0.032 - 0.03 (effects)
    assert fx.net_contact_force(F, x, K1, K2) == pytest.approx(0.4368, rel=1e-13)
    assert fx.net_contact_force(F, x, K1, K2, K5, Kc, xc) == pytest.approx(0.3748, rel=1e-13)
    xs, vs, Fs, K5s, Kcs, xcs = _u(0, 0.01), _u(-0.3, 0.3), _u(0, 1), _u(0, 1e12), _u(0, 30), _u(-0.005, 0.005)
    spring = K1 * xs ** 3 + K2 * xs + K5s * xs ** 5 + Kcs * (xs - xcs)
    acc = _vec_equals_scalars(lambda x_, v_, F_, K5_, Kc_, xc_: fx.diaphragm_acceleration(
        x_, v_, F_, K1, K2, C, m, fx.effect_spring_force(x_, K5_, Kc_, xc_)), xs, vs, Fs, K5s, Kcs, xcs)
    assert np.allclose(acc, (Fs - C * vs - spring) / m, rtol=1e-12, atol=1e-12)
    net = _vec_equals_scalars(fx.net_contact_force, Fs, xs, K1, K2, K5s, Kcs, xcs)
    assert np.allclose(net, Fs - spring, rtol=1e-12, atol=1e-15)


def test_core_state_rates():
    # heating: (8 K/W * 0.64 A^2 * 16 Ohm - 10 K)/4 s = 17.98 K/s; creep: 1.5 mm / 0.5 s; lag: 0.2/5 ms
    assert fx.thermal_rate(10.0, 0.8, 16.0, 8.0, 4.0) == pytest.approx(17.98, rel=1e-14)
    assert fx.creep_rate(0.002, 0.0005, 0.5) == pytest.approx(0.003, rel=1e-14)
    assert fx.sensor_rate(0.3, 0.1, 0.005) == pytest.approx(40.0, rel=1e-14)
    dT, I, RT, Rth, tau = _u(0, 80), _u(-1, 1), _u(10, 20), _u(0, 20), _u(0.5, 5)
    assert np.allclose(_vec_equals_scalars(fx.thermal_rate, dT, I, RT, Rth, tau), (Rth * I ** 2 * RT - dT) / tau,
                       rtol=1e-13, atol=1e-13)
    x, xc = _u(-0.01, 0.01), _u(-0.01, 0.01)
    assert np.allclose(_vec_equals_scalars(fx.creep_rate, x, xc, tau), (x - xc) / tau, rtol=1e-14, atol=0)
    assert np.allclose(_vec_equals_scalars(fx.sensor_rate, x, xc, tau), (x - xc) / tau, rtol=1e-14, atol=0)


def test_scalar_model_rhs_is_the_core_at_random_states():
    """EffectDynamics.rhs (the FMU's right-hand side) against the definitions written here, every mode."""
    from fmu_src.model import BLOCKED, CONTACT, FREE
    kw = {k: v for d in ON.values() for k, v in d.items()}
    p = P.with_(r0=0.004, **kw)
    dyn = EffectDynamics(p)
    assert dyn.state_names == ("I", "x", "v", "dT", "xc", "x_sensor", "F_sensor")
    a = p.a
    for _ in range(20):
        I, x, v, dT, xc, xs, Fs = (RNG.uniform(0, 1), RNG.uniform(-0.002, 0.0039), RNG.uniform(-0.3, 0.3),
                                   RNG.uniform(0, 60), RNG.uniform(-0.002, 0.004), RNG.uniform(0, 0.004),
                                   RNG.uniform(0, 0.5))
        V = RNG.uniform(0, 15)
        for mode in (FREE, CONTACT, BLOCKED):
            xm, vm = (x, v) if mode == FREE else ((p.r0, 0.0) if mode == CONTACT else (0.0, 0.0))
            r = p.r0 - xm
            Rt = p.R * (1 + ALPHA * dT)
            Lx = p.L * (1 + p.lam * (a * a / (a * a + r * r)) ** 1.5)
            dLdx = 3 * p.L * p.lam * a ** 3 * r / (a * a + r * r) ** 2.5
            F = p.Em * I * I * G(r) / (1 + p.ksat * (p.kB * I) ** 2)
            acc = (F - p.C * vm - p.K1 * xm ** 3 - p.K2 * xm - p.K5 * xm ** 5 - p.Kc * (xm - xc)) / p.m
            want = [(V - Rt * I - I * vm * dLdx) / Lx, vm if mode == FREE else 0.0, acc if mode == FREE else 0.0,
                    (p.Rth * I * I * Rt - dT) / p.tau_th, (xm - xc) / p.tau_c, (xm - xs) / p.tau_s,
                    (F - Fs) / p.tau_s]
            got = dyn.rhs([I, x, v, dT, xc, xs, Fs], V, mode)
            assert got == pytest.approx(want, rel=1e-7, abs=1e-9), mode     # G: spline vs quadrature
        y = [I, p.r0, 0.0, dT, xc, xs, Fs]
        spring = p.K1 * p.r0 ** 3 + p.K2 * p.r0 + p.K5 * p.r0 ** 5 + p.Kc * (p.r0 - xc)
        F0 = p.Em * I * I * 1.5 * p.kB ** 2 / p.a / (1 + p.ksat * (p.kB * I) ** 2)     # G(0) = 1.5 kB^2/a
        assert dyn.net_contact_force(y) == pytest.approx(F0 - spring, rel=1e-7, abs=1e-9)


# ----------------------------------------------------------------------------------------- coil heating
def test_coil_heating_steady_current_and_transient():
    Rth, tau = 8.0, 0.05
    p = P.with_(r0=0.002, blocked=True, Rth=Rth, tau_th=tau)
    t = step_grid(1.5)
    out = simulate(p, t, V0)
    # by hand: dT = Rth*I^2*R*(1 + a dT) with I = V/(R(1 + a dT))  ->  a dT^2 + dT - Rth V^2/R = 0
    c = Rth * V0 ** 2 / P.R
    dT = (-1.0 + math.sqrt(1.0 + 4.0 * ALPHA * c)) / (2.0 * ALPHA)
    assert dT == pytest.approx(Rth * (V0 / (P.R * (1 + ALPHA * dT))) ** 2 * P.R * (1 + ALPHA * dT), rel=1e-12)
    I_inf = V0 / (P.R * (1.0 + ALPHA * dT))
    assert out["I"][-1] == pytest.approx(I_inf, rel=1e-8)
    assert out["I"][-1] < 0.85 * V0 / P.R       # a clear droop (dT ~ 61 K)
    # force follows the drooping current
    assert out["F"][-1] == pytest.approx(P.Em * I_inf ** 2 * G(0.002), rel=1e-8)

    # transient against an independent (I, dT) ODE
    def rhs(_, y):
        I, d = y
        Rt = P.R * (1 + ALPHA * d)
        return [(V0 - Rt * I) / P.L, (Rth * I * I * Rt - d) / tau]
    ref = solve_ivp(rhs, (0, t[-1]), [0.0, 0.0], method="DOP853", rtol=1e-11, atol=1e-12, t_eval=t)
    assert np.max(np.abs(out["I"] - ref.y[0])) < 1e-6 * I_inf


# ----------------------------------------------------------------------------------------- saturation
def test_filler_saturation_blocked_force_ratio():
    ksat = 3.0
    t = step_grid(0.2)
    V = V0 * np.minimum(1.0, t / 0.1)
    for gap in (0.0, 0.004):
        plain = simulate(P.with_(r0=gap, blocked=True), t, V)
        sat = simulate(P.with_(r0=gap, blocked=True, ksat=ksat), t, V)
        assert np.array_equal(plain["I"], sat["I"])      # the circuit is unchanged
        k = plain["I"] > 1e-3
        Bsat = 1.0 / math.sqrt(ksat)
        want = 1.0 / (1.0 + (P.kB * plain["I"][k] / Bsat) ** 2)
        assert np.allclose(sat["F"][k] / plain["F"][k], want, rtol=1e-12, atol=0)
    assert sat["F"][-1] / plain["F"][-1] < 0.87


def test_filler_saturation_static_equilibrium():
    p = P.with_(ksat=3.0)
    I = V0 / p.R
    f = lambda x: p.K1 * x ** 3 + p.K2 * x - p.Em * I * I * G(p.r0 - x) / (1 + p.ksat * (p.kB * I) ** 2)
    x_eq = brentq(f, 0.0, 0.5 * p.r0, xtol=1e-16, rtol=1e-15)
    out = simulate(p, np.linspace(0.0, 3.0, 31), V0)
    assert out["x"][-1] == pytest.approx(x_eq, rel=1e-7)


# ----------------------------------------------------------------------------------------- creep
def _equilibrium(p, stiff_extra=0.0, K5=0.0):
    I = V0 / p.R
    f = lambda x: p.K1 * x ** 3 + (p.K2 + stiff_extra) * x + K5 * x ** 5 - p.Em * I * I * G(p.r0 - x)
    return brentq(f, 0.0, 0.5 * p.r0, xtol=1e-16, rtol=1e-15)


def test_creep_early_stiffness_and_long_time_relaxation():
    Kc = 20.0
    x_plain = _equilibrium(P)
    x_stiff = _equilibrium(P, stiff_extra=Kc)
    assert x_stiff < 0.8 * x_plain
    # dashpot much slower than the mechanics: after the ringing the diaphragm sits at the (K + Kc) equilibrium
    early = simulate(P.with_(Kc=Kc, tau_c=1e4), np.linspace(0.0, 0.6, 7), V0)
    assert early["x"][-1] == pytest.approx(x_stiff, rel=2e-4)      # xc/x ~ 0.6 s / 1e4 s
    # and creeps toward the coil: relaxed (tau_c short) it is the plain model's equilibrium
    late = simulate(P.with_(Kc=Kc, tau_c=0.1), np.linspace(0.0, 4.0, 41), V0)
    assert late["x"][-1] == pytest.approx(x_plain, rel=1e-7)
    # in between: monotonic creep after the mechanical transient while the current is steady
    mid = simulate(P.with_(Kc=Kc, tau_c=0.5), step_grid(3.0), V0)
    seg = mid["x"][500:]
    assert np.all(np.diff(seg) > 0) and seg[0] < 0.85 * x_plain and 0.97 * x_plain < seg[-1] < x_plain


def test_creep_recovers_slowly_after_switch_off():
    t = step_grid(2.0)
    V = np.where(t < 1.0, V0, 0.0)
    plain = simulate(P, t, V)
    creep = simulate(P.with_(Kc=20.0, tau_c=0.5), t, V)
    k = np.searchsorted(t, 1.3)
    assert abs(plain["x"][k]) < 1e-6            # plain: back at rest 0.3 s after switch-off
    assert creep["x"][k] > 1e-5                 # creep: still displaced (branch force holds it)


# ----------------------------------------------------------------------------------------- edge stiffening
@pytest.mark.parametrize("gap", [0.009, 0.006])
def test_edge_stiffening_static_equilibrium(gap):
    K5 = 2e11
    p = P.with_(r0=gap, K5=K5)
    out = simulate(p, np.linspace(0.0, 3.0, 31), V0)
    x_eq = _equilibrium(p, K5=K5)
    assert out["x"][-1] == pytest.approx(x_eq, rel=1e-7)
    assert x_eq < _equilibrium(p.with_(K5=0.0))


# ----------------------------------------------------------------------------------------- contact with new force terms
@pytest.mark.parametrize("kw", [dict(K5=2e11), dict(Kc=10.0, tau_c=1e4), dict(ksat=3.0), dict(lam=0.3)],
                         ids=["K5", "creep", "ksat", "lam"])
def test_release_from_contact_at_analytic_time(kw):
    """On the coil face with V = 0: released when Em I^2 G(0) s(I) = spring + K5 r0^5 + Kc (r0 - xc)."""
    p = P.with_(r0=0.003, **kw)
    m = ActuatorModel(p)
    m.reset()
    m.advance(0.5, V0)
    assert m.outputs()["contact"]
    I0 = m.outputs()["I"]
    G0 = 1.5 * p.kB ** 2 / p.a       # G(0) by hand
    S = (p.K1 * p.r0 ** 2 + p.K2) * p.r0 + p.K5 * p.r0 ** 5 + p.Kc * p.r0   # xc ~ 0 (tau_c = 1e4 s)
    # Em G0 I^2 / (1 + ksat kB^2 I^2) = S
    I_rel = math.sqrt(S / (p.Em * G0 - S * p.ksat * p.kB ** 2))
    L_contact = p.L * (1.0 + p.lam)  # L(x = r0) = L (1 + lam)
    t_rel = L_contact / p.R * math.log(I0 / I_rel)
    t = 0.5
    while m.outputs()["contact"]:
        t += 1e-5
        m.advance(t, 0.0)
    assert t - 0.5 == pytest.approx(t_rel, abs=2e-5)


# ----------------------------------------------------------------------------------------- motional EMF
def test_motional_emf_flux_balance_dip_and_rest():
    lam, gap = 0.3, 0.005
    p = P.with_(r0=gap, lam=lam)
    h = 1e-5
    t = np.round(np.arange(0.0, 0.25 + 0.5 * h, h), 12)
    out = simulate(p, t, V0)
    a = p.a
    Lx = p.L * (1.0 + lam * (a * a / (a * a + (gap - out["x"]) ** 2)) ** 1.5)
    flux = Lx * out["I"]
    # d(L(x) I)/dt = V - R I  ->  L(x) I = integral (V - R I) dt
    rhs = np.concatenate([[0.0], np.cumsum(0.5 * h * ((V0 - p.R * out["I"][1:]) + (V0 - p.R * out["I"][:-1])))])
    assert np.max(np.abs(flux - rhs)) < 2e-5 * np.max(flux)
    # the current dips below the RL exponential with the inductance frozen at rest while x moves toward the coil
    L_rest = p.L * (1.0 + lam * (a * a / (a * a + gap * gap)) ** 1.5)
    I_frozen = V0 / p.R * -np.expm1(-t * p.R / L_rest)
    moving = out["v"] > 0.02
    assert moving.sum() > 1000
    assert np.all(out["I"][moving] < I_frozen[moving])
    assert np.max(I_frozen - out["I"]) > 1e-3
    # at rest: V/R
    rest = simulate(p, np.linspace(0.0, 1.0, 11), V0)
    assert abs(rest["v"][-1]) < 1e-12 and rest["I"][-1] == pytest.approx(V0 / p.R, rel=1e-9)
    # blocked (no motion): an exact RL exponential with L(x = 0) at the gap
    bl = simulate(p.with_(blocked=True), t[::100], V0)
    assert np.allclose(bl["I"], V0 / p.R * -np.expm1(-t[::100] * p.R / L_rest), rtol=0, atol=1e-6)


# ----------------------------------------------------------------------------------------- sensor lag
def _first_order_filter(t, u, tau):
    """Exact response of y' = (u - y)/tau to u linear between samples, y(0) = u(0)."""
    y = np.empty_like(u)
    y[0] = u[0]
    for k in range(len(t) - 1):
        h = t[k + 1] - t[k]
        e = math.exp(-h / tau)
        y[k + 1] = e * y[k] + (1 - e) * u[k] + (u[k + 1] - u[k]) * (1 - tau / h * (1 - e))
    return y


@pytest.mark.parametrize("blocked", [False, True])
def test_sensor_lag_is_the_first_order_filtered_output(blocked):
    tau = 0.004
    h = 2e-5
    t = np.round(np.arange(0.0, 0.15 + 0.5 * h, h), 12)
    V = np.where(t < 0.1, V0, 0.0)
    p = P.with_(r0=0.006, blocked=blocked, tau_s=tau)
    out = simulate(p, t, V)
    plain = simulate(P.with_(r0=0.006, blocked=blocked), t, V)
    # the lag does not change the physics (to the integrator tolerance: other step sizes)
    assert np.max(np.abs(out["x"] - plain["x"])) <= 1e-6 * max(np.max(np.abs(plain["x"])), 1e-12)
    assert np.max(np.abs(out["F"] - plain["F"])) <= 1e-6 * np.max(plain["F"])
    for sensed, true in (("x_sensor", "x"), ("F_sensor", "F")):
        ref = _first_order_filter(t, out[true], tau)
        scale = max(np.max(np.abs(out[true])), 1e-12)
        assert np.max(np.abs(out[sensed] - ref)) < 1e-6 * scale, sensed
        if scale > 1e-9:
            assert np.max(np.abs(out[sensed] - out[true])) > 0.05 * scale    # a visible lag


# ----------------------------------------------------------------------------------------- every effect vs an independent ODE
def reference_free(p: Params, V: float, t) -> dict:
    """Free mode (no contact), all effects, written from the definitions; G by quadrature."""
    a, r0 = p.a, p.r0

    def rhs(_, y):
        I, x, v, dT, xc, xs, Fs = y
        r = r0 - x
        Rt = p.R * (1 + ALPHA * dT)
        Lx = p.L * (1 + p.lam * (a * a / (a * a + r * r)) ** 1.5)
        dLdx = p.L * p.lam * 3 * a ** 3 * r / (a * a + r * r) ** 2.5
        dI = (V - Rt * I - I * dLdx * v) / Lx
        F = p.Em * I * I * G(r, p) / (1 + p.ksat * (p.kB * I) ** 2)
        spring = p.K1 * x ** 3 + p.K2 * x + p.K5 * x ** 5 + p.Kc * (x - xc)
        return [dI, v, (F - p.C * v - spring) / p.m,
                (p.Rth * I * I * Rt - dT) / p.tau_th if p.Rth else 0.0,
                (x - xc) / p.tau_c if p.Kc else 0.0,
                (x - xs) / p.tau_s if p.tau_s else 0.0,
                (F - Fs) / p.tau_s if p.tau_s else 0.0]
    sol = solve_ivp(rhs, (t[0], t[-1]), [0.0] * 7, method="DOP853", rtol=1e-10,
                    atol=[1e-12, 1e-13, 1e-12, 1e-9, 1e-13, 1e-13, 1e-12], t_eval=t)
    assert sol.success
    I, x, v, dT, xc, xs, Fs = sol.y
    return {"I": I, "x": x, "x_sensor": xs if p.tau_s else x, "F_sensor": Fs}


@pytest.mark.parametrize("name", list(ON) + ["all"])
def test_trajectory_against_independent_ode(name):
    kw = {k: v for d in ON.values() for k, v in d.items()} if name == "all" else ON[name]
    p = P.with_(**kw)
    t = step_grid(0.3)
    out = simulate(p, t, V0)
    ref = reference_free(p, V0, t)
    assert not out["contact"].any()
    for k in ("I", "x", "x_sensor"):
        err = np.max(np.abs(out[k] - ref[k])) / np.max(np.abs(ref[k]))
        assert err < 1e-6, (k, err)
    if p.tau_s:
        assert np.max(np.abs(out["F_sensor"] - ref["F_sensor"])) < 1e-6 * np.max(ref["F_sensor"])


# ----------------------------------------------------------------------------------------- FMU = Python model
@pytest.mark.parametrize("name", list(ON) + ["all"])
def test_fmu_equals_python_model_with_effect(fmu_path, name):
    from harness.sim import fmurun
    kw = {k: v for d in ON.values() for k, v in d.items()} if name == "all" else ON[name]
    p = P.with_(r0=0.003, **kw)
    t = step_grid(0.35)
    V = V0 * (1.0 + 0.3 * np.sin(2 * np.pi * 5.0 * t)) * (t < 0.25)     # pulls in, then released
    fm = fmurun.run(p, t, V, fmu_path=fmu_path)
    py = simulate(p, t, V)
    for k in ("x", "v", "F", "I", "B", "x_sensor", "F_sensor"):
        assert np.max(np.abs(fm[k] - py[k])) <= 1e-9 * np.max(np.abs(py[k])), k
    assert np.array_equal(fm["contact"].astype(bool), py["contact"])
    assert py["contact"].any() and not py["contact"][-1]


# ----------------------------------------------------------------------------------------- rig
def test_effect_params_mapping():
    from harness.data import rig
    base = rig.true_params(20, 45)
    for name in EFFECTS:
        off = rig.effect_params(name, 0.0, base)
        assert set(off) == set(EFFECTS[name].params) and all(v == 0.0 for v in off.values())
        one, two = rig.effect_params(name, 1.0, base), rig.effect_params(name, 2.0, base)
        sw = EFFECTS[name].switch
        assert one[sw] > 0 and two[sw] == pytest.approx(2 * one[sw], rel=1e-15)
        validate(one)
        assert active_effects(base.with_(**one)) == (name,)
        assert name in rig.EFFECT_MAGNITUDES
    assert rig.effect_params("coil_heating", 1.0, base) == {"Rth": 8.0, "tau_th": 4.0}
    with pytest.raises(ValueError, match="known effects: coil_heating, filler_saturation"):
        rig.effect_params("warp_drive", 1.0, base)
    with pytest.raises(ValueError, match="magnitude"):
        rig.effect_params("sensor_lag", -1.0, base)
    with pytest.raises(ValueError, match=r"unknown effect.*warp_drive.*known effects: coil_heating"):
        rig.apply_effects(base, {"sensor_lag": 1.0, "warp_drive": 1.0})


def test_rig_hides_effects_in_the_data(fmu_path, tmp_path):
    from harness.data import rig
    from harness.data.dataset import read_dataset
    effects = {"sensor_lag": 1.0, "coil_heating": 1.0}
    out = tmp_path / "eff"
    virtual_rig.generate_dataset(out, seed=5, samples=[(20, 45)], fmu_path=fmu_path, effects=effects, workers=1,
                         progress=False)
    m = json.loads((out / "manifest.json").read_text())
    assert m["rig"]["effects"] == {"coil_heating": 1.0, "sensor_lag": 1.0}
    tp = m["rig"]["true_parameters"]["W20-D45"]
    assert tp["Rth_K_per_W"] == 8.0 and tp["tau_th_s"] == 4.0 and tp["tau_s_s"] == 0.005
    assert tp["ksat_per_T2"] == 0.0 and tp["lam_1"] == 0.0 and "K5_N_per_m5" in tp and "Kc_N_per_m" in tp
    truth = rig.params_from_json(tp)
    assert active_effects(truth) == ("coil_heating", "sensor_lag")
    assert set(m["rig"]["effect_definitions"]) == set(effects)

    ds = read_dataset(out)
    ts = ds.sample("W20-D45").tests["T5"]
    t = ts.time_s
    # coil heating: the current droops during the hold (plain rig: flat within noise)
    first = ts.current_A[(t >= protocol.PRE_STEP_S + 0.3) & (t < protocol.PRE_STEP_S + 1.3)].mean()
    last = ts.current_A[t >= t[-1] - 1.0].mean()
    assert last < 0.96 * first
    # sensor lag: the laser reads x_sensor (the lagged displacement), not x
    p = truth.with_(r0=ts.gap_mm / 1000)
    clean = simulate(p, t, ts.voltage_V)
    rise = (t >= protocol.PRE_STEP_S) & (t < protocol.PRE_STEP_S + 0.1)
    lagged = ts.displacement_mm - clean["x_sensor"] * 1e3
    unlagged = ts.displacement_mm - clean["x"] * 1e3
    assert np.std(lagged) == pytest.approx(rig.LASER.noise_floor, rel=0.15)
    assert np.mean(unlagged[rise]) < -10 * rig.LASER.noise_floor     # behind during the rise
    # blocked force (T8) through the lagged transducer too
    t8 = ds.sample("W20-D45").tests["T8"]
    c8 = simulate(truth.with_(r0=t8.gap_mm / 1000, blocked=True), t8.time_s, t8.voltage_V)
    assert np.std(t8.force_N - c8["F_sensor"]) == pytest.approx(rig.FORCE.noise_floor, rel=0.15)
    # T1 sweep with heating: the steady current reads below V/R
    assert np.all(ds.sample("W20-D45").tests["T1"].current_A < 0.99 * V0 / truth.R)
    # same seed, same bytes (effects given in another order)
    again = tmp_path / "again"
    virtual_rig.generate_dataset(again, seed=5, samples=[(20, 45)], fmu_path=fmu_path,
                         effects={"coil_heating": 1.0, "sensor_lag": 1.0}, workers=1, progress=False)
    files = sorted(f.relative_to(out) for f in out.rglob("*") if f.is_file())
    assert len(files) == 9
    for f in files:
        assert (out / f).read_bytes() == (again / f).read_bytes(), f


def test_spring_terms_from_a_parameter_mapping():
    """restoring_force_of / tangent_stiffness_of (the harness's step-size bounds) against the formulas written
    out by hand: (K1 x^2 + K2) x + K5 x^5 (the creep branch relaxed: no force) and 3 K1 x^2 + K2 + 5 K5 x^4 + Kc,
    on floats and per-run arrays; an effect off (0) adds nothing."""
    from fmu_src.effects import restoring_force_of, tangent_stiffness_of
    p = {"K1": 2.0e5, "K2": 40.0, "K5": 3.0e9, "Kc": 8.0}
    x = 0.002
    assert restoring_force_of(x, p) == pytest.approx((2.0e5 * 4e-6 + 40.0) * 0.002 + 3.0e9 * 0.002 ** 5, rel=1e-14)
    assert tangent_stiffness_of(x, p) == pytest.approx(3 * 2.0e5 * 4e-6 + 40.0 + 5 * 3.0e9 * 0.002 ** 4 + 8.0,
                                                       rel=1e-14)
    arr = {k: np.array([v, 0.0 if k in ("K5", "Kc") else v]) for k, v in p.items()}
    f, k = restoring_force_of(np.array([x, x]), arr), tangent_stiffness_of(np.array([x, x]), arr)
    assert f[1] == pytest.approx((2.0e5 * 4e-6 + 40.0) * 0.002, rel=1e-14) and f[0] > f[1]
    assert k[1] == pytest.approx(3 * 2.0e5 * 4e-6 + 40.0, rel=1e-14) and k[0] > k[1]
