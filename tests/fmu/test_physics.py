"""Physics core against independent formulas and hand-computed cases."""
import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from fmu_src import coil, diaphragm, field
from fmu_src.model import ActuatorModel, simulate
from fmu_src.specs import MU0, Params, validate

P = Params()


def biot_savart_axis(I, r, a, N):
    """On-axis field of a circular loop by numerically integrating Biot-Savart (independent of Eq. 2)."""
    def dBz(phi):
        # element a*dphi at (a cos phi, a sin phi, 0); field point (0, 0, r); z-component of dl x R
        return MU0 * N * I / (4 * math.pi) * a * a / (a * a + r * r) ** 1.5
    return quad(dBz, 0, 2 * math.pi)[0]


@pytest.mark.parametrize("r", [0.0, 0.002, 0.009, 0.03])
def test_on_axis_field_equals_exact_loop_field(r):
    I = 0.8
    N = 2.0 * P.a * P.kB / MU0    # effective turn count from kB = mu0*N/(2a)
    exact = MU0 * N * I * P.a**2 / (2 * (P.a**2 + r * r) ** 1.5)
    eq2 = I * field.field_per_amp(r, 0.0, P.a, P.kB)
    assert eq2 == pytest.approx(exact, rel=1e-12)
    assert eq2 == pytest.approx(biot_savart_axis(I, r, P.a, N), rel=1e-10)
    assert float(field.axial_field(I, r, P.a, P.kB)) == pytest.approx(exact, rel=1e-12)


def test_field_at_coil_face_is_kB_times_current():
    assert float(field.field_per_amp(0.0, 0.0, P.a, P.kB)) == pytest.approx(P.kB, rel=1e-14)


def test_radial_derivative_matches_finite_difference():
    for r in (0.001, 0.005, 0.02):
        for th in (0.0, 0.4, 1.2):
            h = 1e-7
            fd = (field.field_per_amp(r + h, th, P.a, P.kB) - field.field_per_amp(r - h, th, P.a, P.kB)) / (2 * h)
            assert float(field.dfield_dr_per_amp(r, th, P.a, P.kB)) == pytest.approx(float(fd), rel=1e-6)


def test_force_kernel_against_adaptive_quadrature_and_hand_value():
    # hand-derived: at r = 0, b = kB cos(th), db/dr = -(9/2) kB cos(th) sin(th)/a  ->  G(0) = 1.5 kB^2 / a
    assert float(field.force_kernel(0.0, P.a, P.D, P.kB)[0]) == pytest.approx(1.5 * P.kB**2 / P.a, rel=1e-12)
    for r in (0.001, 0.004, 0.012, 0.025):
        f = lambda th: -field.field_per_amp(r, th, P.a, P.kB) * field.dfield_dr_per_amp(r, th, P.a, P.kB)
        q = quad(f, 0, math.atan(P.D / (2 * r)), epsabs=0, epsrel=1e-12)[0]
        assert float(field.force_kernel(r, P.a, P.D, P.kB)[0]) == pytest.approx(q, rel=1e-10)


def test_kernel_table_matches_quadrature():
    k = field.make_kernel(P.a, P.D, P.kB, P.r0)
    r = np.linspace(0.0, k.r_max, 997)
    exact = field.force_kernel(r, P.a, P.D, P.kB)
    assert np.max(np.abs(k.eval(r) / exact - 1)) < 1e-8
    assert max(abs(k(float(ri)) / e - 1) for ri, e in zip(r, exact)) < 1e-8


def test_force_decreases_with_gap_and_grows_with_diameter():
    r = np.linspace(0.0, 0.025, 50)
    g = field.force_kernel(r, P.a, P.D, P.kB)
    assert np.all(np.diff(g) < 0)
    assert field.force_kernel(0.005, P.a, 0.060, P.kB)[0] > field.force_kernel(0.005, P.a, 0.030, P.kB)[0]


def test_steady_current_and_time_constant():
    V = coil.voltage_for_field(0.23, P.kB, P.R)
    tau = P.L / P.R
    t = np.array([0.0, tau, 2 * tau, 1.0])
    out = simulate(P, t, V)
    assert out["I"][-1] == pytest.approx(V / P.R, rel=1e-9)
    assert out["I"][1] == pytest.approx(V / P.R * (1 - math.exp(-1)), rel=1e-8)
    assert out["I"][2] == pytest.approx(V / P.R * (1 - math.exp(-2)), rel=1e-8)
    assert V / P.R * P.kB == pytest.approx(0.23)


def equilibrium(p, I):
    g = lambda x: diaphragm.spring_force(x, p.K1, p.K2) - p.Em * I * I * field.force_kernel(p.r0 - x, p.a, p.D, p.kB)[0]
    return brentq(g, 0.0, p.r0 * 0.5, xtol=1e-15)


@pytest.mark.parametrize("gap", [0.009, 0.012, 0.02])
def test_static_equilibrium(gap):
    p = P.with_(r0=gap)
    V = coil.voltage_for_field(0.23, p.kB, p.R)
    out = simulate(p, np.linspace(0, 3.0, 31), V)
    x_eq = equilibrium(p, V / p.R)
    assert out["x"][-1] == pytest.approx(x_eq, rel=1e-7)
    assert not out["contact"].any()
    # and the force output is the magnetic force at that displacement
    assert out["F"][-1] == pytest.approx(diaphragm.spring_force(x_eq, p.K1, p.K2), rel=1e-6)


def test_pull_in_contact_without_bounce_or_penetration():
    p = P.with_(r0=0.003)
    V = coil.voltage_for_field(0.23, p.kB, p.R)
    # independent check that no equilibrium exists: net force toward the coil at every x in [0, r0]
    I = V / p.R
    xs = np.linspace(0, p.r0, 400)
    net = p.Em * I * I * field.force_kernel(p.r0 - xs, p.a, p.D, p.kB) - diaphragm.spring_force(xs, p.K1, p.K2)
    assert np.all(net > 0)
    t = np.arange(0, 1.0, 1e-4)
    out = simulate(p, t, V)
    assert out["x"].max() <= p.r0 + 1e-15
    k = np.argmax(out["contact"])
    assert k > 0 and out["contact"][k:].all(), "must stay in contact once it touches (no bounce)"
    assert np.all(out["x"][k:] == p.r0) and np.all(out["v"][k:] == 0.0)


def test_release_from_contact_at_analytic_time():
    p = P.with_(r0=0.003)
    V = coil.voltage_for_field(0.23, p.kB, p.R)
    m = ActuatorModel(p)
    m.reset()
    m.advance(0.5, V)
    assert m.outputs()["contact"]
    I0 = m.outputs()["I"]
    # switch off: I = I0 exp(-t R/L); released when Em I^2 G(0) = K(r0) r0
    I_rel = math.sqrt(diaphragm.spring_force(p.r0, p.K1, p.K2) / (p.Em * 1.5 * p.kB**2 / p.a))
    t_rel = p.L / p.R * math.log(I0 / I_rel)
    t = 0.5
    while m.outputs()["contact"]:
        t += 1e-5
        m.advance(t, 0.0)
    assert t - 0.5 == pytest.approx(t_rel, abs=2e-5)
    m.advance(t + 0.5, 0.0)
    assert m.outputs()["x"] < 1e-4 and not m.outputs()["contact"]


@pytest.mark.parametrize("gap", [0.0, 0.002, 0.01])
def test_blocked_force(gap):
    p = P.with_(r0=gap, blocked=True)
    V = coil.voltage_for_field(0.23, p.kB, p.R)
    out = simulate(p, np.linspace(0, 1.0, 11), V)
    I = V / p.R
    assert np.all(out["x"] == 0.0) and np.all(out["v"] == 0.0)
    G = 1.5 * p.kB**2 / p.a if gap == 0.0 else field.force_kernel(gap, p.a, p.D, p.kB)[0]
    assert out["F"][-1] == pytest.approx(p.Em * I * I * G, rel=1e-8)


@pytest.mark.parametrize("name,value", [("m", 0.0), ("L", -1.0), ("R", 0.0), ("D", 0.0), ("r0", -0.001),
                                        ("Em", float("nan")), ("K2", float("inf"))])
def test_bad_parameters_are_named(name, value):
    with pytest.raises(ValueError, match=rf"parameter {name}\b"):
        validate({name: value})
    with pytest.raises(ValueError, match=rf"parameter {name}\b"):
        ActuatorModel(P.with_(**{name: value}))
