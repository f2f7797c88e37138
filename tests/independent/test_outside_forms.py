"""The independent generator's effects outside the catalogue (issue 22's data) do what their texts say.

Each form is checked against a formula written here by hand (statics solved with ``scipy.optimize.brentq``,
linear circuits with ``scipy.linalg.expm``, first-order networks in closed form), never against the
project's code: these datasets are what the discovery is judged on.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import brentq

from tests.independent import physics as ph
from tests.independent.generator import OUTSIDE_FORMS, OUTSIDE_KIND, true_params, with_effects
from tests.independent.space import RigDescription

P = true_params(20, 45)
V_023 = P.R_Ohm * 0.23 / P.kB_T_per_A         # the step of T5/T8 (0.23 T steady)
T = np.linspace(0.0, 2.8, 2801)
T_STEP = 0.1


def _run(p, r0_m, blocked=False, V=V_023, t=T):
    return ph.simulate(p, r0_m, blocked, ph.step_drive(T_STEP, V), t)


def _static_x(p, r0_m, I_A, soft=1.0):
    """x [m] of the force balance F(r0 - x) = soft (K2 x + K1 x^3) + K_even x^2 + K5 x^5, by bisection."""
    G = ph.kernel_table(p.a_m, p.D_m, p.kB_T_per_A)

    def g(x):
        return (p.Em_N_m_per_T2 * I_A**2 * G(r0_m - x) - soft * (p.K2_N_per_m * x + p.K1_N_per_m3 * x**3)
                - p.K_even_N_per_m2 * x**2 - p.K5_N_per_m5 * x**5)
    return brentq(g, 0.0, 0.8 * r0_m, xtol=1e-15)


def test_every_outside_form_has_a_kind_and_switches_something_on():
    assert set(OUTSIDE_KIND) == set(OUTSIDE_FORMS)
    assert set(OUTSIDE_KIND.values()) == {"mechanical", "coil", "reading"}
    for name in OUTSIDE_FORMS:
        assert with_effects(P, {name: 1.0}) != P, name
        RigDescription(effect=(name, 1.5))              # a description accepts it
    with pytest.raises(ValueError, match="unknown effect"):
        with_effects(P, {"no_such_form": 1.0})


def test_laser_nonlinearity_is_the_stated_polynomial_of_the_true_displacement():
    p = with_effects(P, {"laser_nonlinearity": 1.0})
    r, c = _run(p, 0.005), _run(P, 0.005)
    x = c["x_m"]
    np.testing.assert_allclose(r["x_m"], x, rtol=0, atol=1e-15)        # the motion itself is untouched
    np.testing.assert_allclose(r["x_sensor_m"], x + 8.0 * x**2 + 500.0 * x**3, rtol=0, atol=1e-13)


def test_dome_prestress_static_deflection_by_hand():
    p = with_effects(P, {"dome_prestress": 1.0})
    assert p.K_even_N_per_m2 == pytest.approx(0.15 * P.K2_N_per_m / (0.045 / 20.0), rel=1e-14)
    r = _run(p, 0.005)
    x_hand = _static_x(p, 0.005, V_023 / P.R_Ohm)
    assert r["x_m"][-1] == pytest.approx(x_hand, rel=2e-4)
    assert r["x_m"][-1] < _static_x(P, 0.005, V_023 / P.R_Ohm)          # stiffer toward the coil


def test_silicone_heating_two_node_temperature_and_softened_statics():
    p = with_effects(P, {"silicone_heating": 1.0})
    r = _run(p, 0.005)
    I = V_023 / P.R_Ohm
    tau1, tau2 = 2.0, 1.0
    for t_s in (1.5, 2.8):
        s = t_s - T_STEP                          # the current settles in ~10 ms: the power is a step of I^2 R
        Td = 6.0 * I * I * P.R_Ohm * (1 - (tau1 * math.exp(-s / tau1) - tau2 * math.exp(-s / tau2)) / (tau1 - tau2))
        x_hand = _static_x(p, 0.005, I, soft=1.0 - 0.004 * Td)
        k = int(round(t_s * 1000))
        assert r["x_m"][k] == pytest.approx(x_hand, rel=3e-3), t_s
    assert r["I_A"][-1] == pytest.approx(I, rel=1e-6)          # the coil itself stays cold (no R(T))


def test_eddy_currents_match_the_two_circuit_matrix_exponential():
    p = with_effects(P, {"eddy_currents": 1.0})
    r = _run(p, 0.002, blocked=True)              # blocked: the current does not depend on the motion
    L, R, k2, tau = P.L_H, P.R_Ohm, 0.4, 0.020
    M = math.sqrt(k2) * L
    Minv = np.linalg.inv(np.array([[L, M], [M, L]]))
    A = Minv @ np.array([[-R, 0.0], [0.0, -L / tau]])
    b = Minv @ np.array([V_023, 0.0])
    xs = -np.linalg.solve(A, b)                   # steady state (I = V/R, Ie = 0)
    assert xs[0] == pytest.approx(V_023 / R, rel=1e-12) and abs(xs[1]) < 1e-12
    for t_s in (0.102, 0.11, 0.13, 0.2, 0.5):
        y = xs - expm(A * (t_s - T_STEP)) @ xs     # from rest
        assert r["I_A"][int(round(t_s * 1000))] == pytest.approx(y[0], rel=2e-5, abs=1e-8), t_s
    # at the step the current rises at V / (L (1 - k^2)), faster than the plain coil's V / L
    y1 = xs - expm(A * 1e-6) @ xs
    assert y1[0] / 1e-6 == pytest.approx(V_023 / (L * (1 - k2)), rel=1e-3)


def test_loadcell_creep_reads_a_step_force_with_two_exponentials():
    p = with_effects(P, {"loadcell_creep": 1.0})
    r, c = _run(p, 0.002, blocked=True), _run(P, 0.002, blocked=True)
    np.testing.assert_allclose(r["F_N"], c["F_N"], rtol=2e-6, atol=1e-9)   # the true force (to solver accuracy)
    F_end = c["F_N"][-1]
    # the force rises with the current (~10 ms), which delays the creep a little: the bound shrinks with time
    for t_s, rel in ((0.3, 1.5e-3), (0.8, 4e-4), (2.0, 1e-4), (2.8, 1e-4)):
        s = t_s - T_STEP
        hand = F_end * (1 - 0.03 * math.exp(-s / 0.3) - 0.02 * math.exp(-s / 3.0))
        assert r["F_sensor_N"][int(round(t_s * 1000))] == pytest.approx(hand, rel=rel), t_s


def test_fluid_drag_changes_the_transient_not_the_statics():
    p = with_effects(P, {"fluid_drag": 1.0})
    r, c = _run(p, 0.005), _run(P, 0.005)
    assert r["x_m"][-1] == pytest.approx(c["x_m"][-1], rel=1e-6)
    x_static = _static_x(P, 0.005, V_023 / P.R_Ohm)
    over_c, over_r = c["x_m"].max() - x_static, r["x_m"].max() - x_static
    assert over_c > 0 and over_r < 0.7 * over_c          # v|v| drag takes energy from the fast rise
    assert np.max(np.abs(r["x_m"] - c["x_m"])) > 20e-6


def test_clamp_friction_force_is_bounded_and_the_rest_within_its_dead_band():
    p = with_effects(P, {"clamp_friction": 1.0})
    act = ph.Actuator(p, 0.004, False)
    assert act.lay.fric and act.lay.n == 4
    r = _run(p, 0.004, V=V_023 * 0.11 / 0.23)
    I = V_023 * 0.11 / 0.23 / P.R_Ohm
    x_static = _static_x(P, 0.004, I)
    k_t = P.K2_N_per_m + 3 * P.K1_N_per_m3 * x_static**2
    assert abs(r["x_m"][-1] - x_static) <= 1.02 * 0.003 / k_t            # stuck within Fc / stiffness
    assert abs(r["x_m"][-1] - x_static) > 0.1 * 0.003 / k_t              # and visibly off the balance
