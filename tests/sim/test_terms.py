"""The generic term set (fmu_src.terms) in the vectorized simulator (harness.sim) and the FMU's integrator,
checked against references written here anew (scipy's solve_ivp on the equations as the term table states
them, hand-solved steady states, exact first-order lags), not against the project's code.

The trick that makes the mechanical terms checkable without the project's force kernel: the magnetic force
is switched down to nothing (Em = 1e-15 N.m/T^2: a 1e-15 N force) and the diaphragm is driven by the
``remanence`` term, c*I, a force linear in the current. Then the whole model is a small ODE the reference
below writes out: the RL coil with the coil terms, the Duffing diaphragm with the force terms, the lag
states, the reading terms.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from fmu_src.model import simulate as fmu_simulate
from fmu_src.specs import Params
from fmu_src.statics import Statics
from fmu_src.terms import TERMS
from harness.sim import core, physics
from harness.sim.settings import Schedule
from harness.sim.simulator import PARAM_FIELDS, Runs, simulate

V_STEP = 6.0          # step voltage [V]
VF = 1e-3             # the smooth sign's velocity [m/s] as the term table states it (dry_friction)
BASE = Params(r0=0.006, Em=1e-15)   # no magnetic force to speak of: the remanence term drives the diaphragm


def _base(x_static=0.2):
    """BASE with the remanence term set so that the steady force c*V/R deflects the linear spring by
    x_static*r0."""
    p = BASE
    return p.with_(c_remanence=x_static * p.r0 * p.K2 / (V_STEP / p.R))


def _reference(p: Params, t, V=V_STEP, blocked=False):
    """solve_ivp of the model as the term table writes it (Em ~ 0: no magnetic force): returns I [A],
    x_sensor [m] on the times t."""
    vf2 = VF * VF

    def f(_, s):
        I, x, v, zP, zI, zD = s
        dI = (V - p.R * I + p.c_eddy_current * (zI - I) - p.c_current_cubic * I ** 3) / p.L
        force = (p.c_remanence * I - (p.K1 * x * x + p.K2) * x - p.C * v - p.c_quad_drag * v * abs(v)
                 - p.c_dry_friction * v / np.sqrt(v * v + vf2) - p.c_even_spring * x * x
                 - p.c_cubic_damping * x * x * v + p.c_heat_softening * x * zP - p.c_dahl_friction * zD)
        dx, dv = (0.0, 0.0) if blocked else (v, force / p.m)
        dzP = (I * I * p.R - zP) / p.tau_P if p.tau_P > 0 else 0.0
        dzI = (I - zI) / p.tau_I if p.tau_I > 0 else 0.0
        # Dahl's presliding state: dz/dx = (1 - z*sign(v))/x_c, x_c = tau_dahl
        dzD = v * (1.0 - zD * np.sign(v)) / p.tau_dahl if p.tau_dahl > 0 else 0.0
        return [dI, dx, dv, dzP, dzI, dzD]

    sol = solve_ivp(f, (0.0, t[-1]), [0.0] * 6, t_eval=t, method="LSODA", rtol=1e-11, atol=1e-14, max_step=1e-3)
    assert sol.success
    I, x = sol.y[0], sol.y[1]
    return I, x + p.c_x_quadratic * x ** 2 + p.c_x_cubic * x ** 3


def _sim(ps, blocked=False, t_end=0.4, V=V_STEP, dt=1e-3):
    runs = Runs(params={k: np.array([getattr(p, k) for p in ps], dtype=float) for k in PARAM_FIELDS},
                blocked=np.full(len(ps), blocked), V=np.full(len(ps), V), dt=dt)
    return simulate(runs, Schedule(t_end=t_end, fine_s=t_end))


# coefficient per term as a fraction of its natural scale (TermSpec.scale), the terms the reference above covers
_COVERED = ("quad_drag", "dry_friction", "even_spring", "cubic_damping", "heat_softening", "eddy_current",
            "current_cubic", "x_quadratic", "x_cubic", "dahl_friction")
_TAUS = {"heat_softening": ("tau_P", 0.05), "eddy_current": ("tau_I", 0.004), "dahl_friction": ("tau_dahl", 2e-5)}
_SMALL = {"dry_friction": 0.05, "dahl_friction": 0.05}   # friction: 1/20 of its natural scale (else it holds x)


def _with_terms(p, ratios: dict):
    kw = {f"c_{n}": r * TERMS[n].scale(p) for n, r in ratios.items()}
    for n in ratios:
        if n in _TAUS:
            kw[_TAUS[n][0]] = _TAUS[n][1]
    return p.with_(**kw)


def _check_against_reference(ratios: dict, tol=2e-5):
    p = _with_terms(_base(), ratios)
    res = _sim([p])
    I_ref, x_ref = _reference(p, res.t)
    fmu = fmu_simulate(p, res.t, np.full(res.t.size, V_STEP), rtol=1e-10)
    for name, x, I in (("harness.sim", res.x[0], res.I[0]), ("FMU", np.asarray(fmu["x_sensor"]), np.asarray(fmu["I"]))):
        ex = np.max(np.abs(x - x_ref)) / np.max(np.abs(x_ref))
        eI = np.max(np.abs(I - I_ref)) / np.max(np.abs(I_ref))
        assert ex < tol and eI < tol, (name, ratios, ex, eI)
    return p, res, x_ref


@pytest.mark.parametrize("name", _COVERED)
def test_each_term_against_the_reference(name):
    """Each term alone at its natural scale: harness.sim and the FMU follow the reference ODE, and the term
    changes the response by far more than the tolerance (a term that did nothing, or had the wrong sign or
    power, would fail)."""
    ratio = {"dry_friction": 0.05, "dahl_friction": 0.05, "current_cubic": 0.3}.get(name, 0.5)
    p, res, x_ref = _check_against_reference({name: ratio})
    I_off, x_off = _reference(p.with_(**{f"c_{name}": 0.0}), res.t)
    effect = max(np.max(np.abs(x_off - x_ref)) / np.max(np.abs(x_ref)), 0.0)
    if TERMS[name].equation == "coil":
        effect = max(effect, np.max(np.abs(I_off - _reference(p, res.t)[0])) / np.max(np.abs(I_off)))
    assert effect > 1e-3, (name, effect)


@settings(max_examples=6, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(ratios=st.dictionaries(st.sampled_from(_COVERED), st.floats(-1.0, 1.0), min_size=1, max_size=4))
def test_term_combinations_against_the_reference(ratios):
    """Any combination of terms, coefficients between -1 and 1 natural scales (signed; dry friction 1/20 of
    that), as long as the diaphragm stays off the coil face and the spring stays restoring."""
    ratios = {n: (abs(r) if TERMS[n].nonnegative else r) * _SMALL.get(n, 1.0) for n, r in ratios.items()}
    _check_against_reference(ratios, tol=5e-5)


@pytest.mark.deep
@settings(max_examples=200, deadline=None, suppress_health_check=list(HealthCheck))
@given(ratios=st.dictionaries(st.sampled_from(_COVERED), st.floats(-1.0, 1.0), min_size=1, max_size=6))
def test_term_combinations_against_the_reference_deep(ratios):
    ratios = {n: (abs(r) if TERMS[n].nonnegative else r) * _SMALL.get(n, 1.0) for n, r in ratios.items()}
    _check_against_reference(ratios, tol=5e-5)


def test_even_spring_static_deflection_by_hand():
    """The steady deflection with the even spring: (K1*x^2 + K2)*x + c*x^2 = c_rem*V/R, solved here by
    brentq, against harness.sim's final value and fmu_src.statics' steady voltage for that deflection."""
    p = _with_terms(_base(), {"even_spring": 0.8})
    F = p.c_remanence * V_STEP / p.R
    x_hand = brentq(lambda x: (p.K1 * x * x + p.K2) * x + p.c_even_spring * x * x - F, 0.0, p.r0)
    res = _sim([p], t_end=1.5)
    assert abs(res.x[0, -1] - x_hand) < 1e-7 * p.r0
    assert abs(Statics(p).voltage_for(x_hand) - V_STEP) < 1e-9 * V_STEP
    # and the heat-softened spring: x*((K1*x^2 + K2) - c*z_P) = c_rem*I with z_P = I^2*R at I = V/R
    q = _with_terms(_base(), {"heat_softening": 0.5})
    I = V_STEP / q.R
    x_soft = brentq(lambda x: (q.K1 * x * x + q.K2 - q.c_heat_softening * I * I * q.R) * x - q.c_remanence * I,
                    0.0, q.r0)
    assert abs(Statics(q).voltage_for(x_soft) - V_STEP) < 1e-9 * V_STEP
    assert abs(_sim([q], t_end=1.5).x[0, -1] - x_soft) < 1e-7 * q.r0


def test_force_reading_terms_blocked():
    """Blocked force readings (the real magnetic force): F_quadratic reads F + c*F^2 of the plain run's force
    exactly; F_creep reads F + c*(z - F), z the first-order lag of F with tau_Fs (an exact lag of the
    piecewise-linear force, written here)."""
    p = Params(r0=0.005, blocked=True)
    dt = 1e-4
    c_q, c_c, tau = 0.8, 0.15, 0.02
    res = _sim([p, p.with_(c_F_quadratic=c_q), p.with_(c_F_creep=c_c, tau_Fs=tau)], blocked=True, t_end=0.15, dt=dt)
    F = res.F[0]
    assert np.max(np.abs(res.F[1] - (F + c_q * F * F))) <= 1e-12 * np.max(F)
    z = np.zeros_like(F)
    E = np.exp(-dt / tau)
    g = tau / dt * (1 - E)
    for k in range(1, F.size):     # exact lag of u linear from F[k-1] to F[k]
        z[k] = F[k] + (z[k - 1] - F[k - 1]) * E - (F[k] - F[k - 1]) * g
    want = F + c_c * (z - F)
    assert np.max(np.abs(res.F[2] - want)) < 1e-4 * c_c * np.max(F)
    assert np.max(np.abs(res.F[2] - F)) > 0.1 * c_c * np.max(F)      # the creep shows


def test_net_contact_force_includes_the_force_terms():
    """On the coil face (x = r0, v = 0) the net contact force gains c_rem*I - c_even*r0^2 + c_soft*r0*z_P +
    c_lag*(z_F - F_face) (hand formula of the terms at x = r0, v = 0), the magnetic force F_face the same."""
    p0 = Params(r0=0.004)
    p = p0.with_(c_remanence=0.02, c_even_spring=300.0, c_heat_softening=2.0, tau_P=1.0, c_force_lag=0.3,
                 tau_F=0.01, c_quad_drag=5.0, c_cubic_damping=1e3, c_dry_friction=0.01)
    runs = Runs(params={k: np.array([getattr(q, k) for q in (p0, p)], dtype=float) for k in PARAM_FIELDS},
                blocked=np.zeros(2, bool), V=np.full(2, 5.0))
    c = physics.constants(runs)
    I, zP, zF = 0.7, 3.0, 0.05
    Y = np.zeros((2, core.NY + 1))
    Y[:, 0], Y[:, 1], Y[:, 2], Y[:, core.NY] = I, p.r0, 0.3, 0.0      # on the face; v ignored there
    Y[1, core.Y_STATES.index("z_P")], Y[1, core.Y_STATES.index("z_F")] = zP, zF
    out = core.rhs(physics.param_blocks(c), c["kt"].coef, Y, np.full(2, 5.0))
    net0, net = out[0, core.NY + 1], out[1, core.NY + 1]
    # F_face: the plain net force plus the spring at r0 (hand: Duffing spring)
    F_face = net0 + (p.K1 * p.r0 ** 2 + p.K2) * p.r0
    want = (p.c_remanence * I - p.c_even_spring * p.r0 ** 2 + p.c_heat_softening * p.r0 * zP
            + p.c_force_lag * (zF - F_face))
    assert abs((net - net0) - want) < 1e-12 * max(abs(want), abs(F_face))


def test_lag_rates_and_the_frozen_lags():
    """A lag in use follows z' = (u - z)/tau (u: I^2*R, F, I, F); a lag no term with a nonzero coefficient uses
    keeps rate 0 even with its time constant 0."""
    p = Params(r0=0.004).with_(c_heat_softening=1.0, tau_P=0.5, c_eddy_current=2.0, tau_I=0.02)
    runs = Runs(params={k: np.array([getattr(p, k)], dtype=float) for k in PARAM_FIELDS},
                blocked=np.zeros(1, bool), V=np.full(1, 5.0))
    c = physics.constants(runs)
    Y = np.zeros((1, core.NY + 1))
    Y[0, :3] = 0.6, 0.001, 0.0
    Y[0, core.NY] = 1.0
    z = {"z_P": 1.0, "z_F": 0.2, "z_I": 0.5, "z_Fs": 0.1}
    for k, v in z.items():
        Y[0, core.Y_STATES.index(k)] = v
    out = core.rhs(physics.param_blocks(c), c["kt"].coef, Y, np.full(1, 5.0))[0]
    assert out[core.Y_STATES.index("z_P")] == pytest.approx((0.6 ** 2 * p.R - 1.0) / 0.5, rel=1e-14)
    assert out[core.Y_STATES.index("z_I")] == pytest.approx((0.6 - 0.5) / 0.02, rel=1e-14)
    assert out[core.Y_STATES.index("z_F")] == 0.0 and out[core.Y_STATES.index("z_Fs")] == 0.0
    # the coil equation with the eddy term: L*I' = V - R*I + c*(z_I - I)
    assert out[0] == pytest.approx((5.0 - p.R * 0.6 + 2.0 * (0.5 - 0.6)) / p.L, rel=1e-13)


def test_zero_coefficients_change_nothing():
    """Terms with coefficient 0 (time constants set or not) leave every output bit-identical, and a run with
    a term on does not change its neighbours' results in a batch."""
    base = Params(r0=0.005)
    ps = [base, base.with_(tau_P=1.0, tau_F=0.1, tau_I=0.01, tau_Fs=2.0, tau_dahl=1e-5),
          base.with_(c_quad_drag=3.0, c_x_cubic=100.0)]
    res = _sim(ps)
    alone = _sim([base])
    assert np.array_equal(res.x[0], res.x[1]) and np.array_equal(res.x[0], alone.x[0])
    assert np.array_equal(res.I[0], alone.I[0]) and not np.array_equal(res.x[2], res.x[0])


_ALL = tuple(TERMS)
_LAG_TAU = {"P": 0.3, "F": 0.01, "I": 0.004, "Fs": 0.05, "dahl": 3e-5}


def _agree(ratios: dict, blocked: bool, tol: float = 2e-5):
    p = Params(r0=0.005, blocked=blocked)
    ratios = {n: (abs(r) if TERMS[n].nonnegative else r) for n, r in ratios.items()}
    kw = {f"c_{n}": r * TERMS[n].scale(p) for n, r in ratios.items()}
    kw.update({f"tau_{TERMS[n].lag}": _LAG_TAU[TERMS[n].lag] for n in ratios if TERMS[n].lag})
    p = p.with_(**kw)
    res = _sim([p], blocked=blocked, t_end=0.3, V=10.0)
    fmu = fmu_simulate(p, res.t, np.full(res.t.size, 10.0), rtol=1e-10)
    y, want = (res.F[0], np.asarray(fmu["F_sensor"])) if blocked else (res.x[0], np.asarray(fmu["x_sensor"]))
    err = np.max(np.abs(y - want)) / np.max(np.abs(want))
    assert err < tol and np.max(np.abs(res.I[0] - np.asarray(fmu["I"]))) < tol * np.max(np.abs(fmu["I"])), (ratios, err)


@settings(max_examples=6, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(ratios=st.dictionaries(st.sampled_from(_ALL), st.floats(-0.3, 0.3), min_size=1, max_size=4),
       blocked=st.booleans())
def test_harness_sim_equals_the_fmu_with_terms(ratios, blocked):
    """With the real magnetic force (contact included) and any terms on, coefficients up to 0.3 natural
    scales: harness.sim (RK4, exact sensor lag) and the FMU's integrator (DP5 at rtol 1e-10) agree to the
    RK4's accuracy."""
    _agree(ratios, blocked)


@pytest.mark.deep
@settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
@given(ratios=st.dictionaries(st.sampled_from(_ALL), st.floats(-0.3, 0.3), min_size=1, max_size=6),
       blocked=st.booleans())
def test_harness_sim_equals_the_fmu_with_terms_deep(ratios, blocked):
    _agree(ratios, blocked)


def test_docs_table_is_generated_from_the_term_table():
    """docs/model.md holds the term library exactly as fmu_src.terms.markdown_table() makes it from TERMS."""
    from pathlib import Path
    from fmu_src.terms import markdown_table
    doc = (Path(__file__).resolve().parents[2] / "docs" / "model.md").read_text()
    assert markdown_table() in doc
    for t in TERMS.values():
        assert f"`c_{t.name}` [{t.unit}]" in doc


def test_params_json_carries_nonzero_terms():
    """extended_params.json and the other parameter files: a term's coefficient and lag time constant round-trip
    with their units in the keys; files without terms hold no term key (as before)."""
    from harness.data.paramsjson import params_from_json, params_to_json
    p = Params().with_(c_quad_drag=2.0, c_heat_softening=-1.5, tau_P=3.0)
    d = params_to_json(p)
    assert d["c_quad_drag_N_s2_per_m2"] == 2.0 and d["c_heat_softening_N_per_m_W"] == -1.5 and d["tau_P_s"] == 3.0
    q = params_from_json(d, "test")
    assert (q.c_quad_drag, q.c_heat_softening, q.tau_P) == (2.0, -1.5, 3.0)
    assert not any(k.startswith("c_") for k in params_to_json(Params()))


def _dahl_loop(x, x_c):
    """Dahl's state along a displacement path x [m], exactly, segment by segment (hand solution of
    dz/dx = (1 - z*s)/x_c on a monotone piece of sign s: z = s - (s - z0)*exp(-|x - x0|/x_c))."""
    z = np.zeros_like(x)
    for k in range(1, x.size):
        dx = x[k] - x[k - 1]
        s = np.sign(dx)
        z[k] = s - (s - z[k - 1]) * np.exp(-abs(dx) / x_c)
    return z


def test_dahl_friction_hysteresis_loop_by_hand():
    """The Dahl lag's rate in the compiled core, integrated along a prescribed displacement cycle (x = A*sin,
    v = x') with RK4 here, against the exact segment solution written above: the state follows
    z = s - (s - z0)*exp(-|dx|/x_c), and the friction force -c*z traces a hysteresis loop (its two branches
    at x = 0 differ by almost 2c)."""
    from fmu_src.terms import LAGS
    x_c, A, w = 2e-5, 2e-4, 2 * np.pi * 5.0
    p = Params(r0=0.004).with_(c_dahl_friction=0.01, tau_dahl=x_c)
    runs = Runs(params={k: np.array([getattr(p, k)], dtype=float) for k in PARAM_FIELDS},
                blocked=np.zeros(1, bool), V=np.zeros(1))
    c = physics.constants(runs)
    P = physics.param_blocks(c)
    iz = core.Y_STATES.index(LAGS["dahl"].state)

    def zdot(t, z):
        Y = np.zeros((1, core.NY + 1))
        Y[0, 1], Y[0, 2], Y[0, iz], Y[0, core.NY] = A * np.sin(w * t), A * w * np.cos(w * t), z, 1.0
        return core.rhs(P, c["kt"].coef, Y, np.zeros(1))[0, iz]

    t = np.linspace(0.0, 0.4, 40001)
    h = t[1] - t[0]
    z = np.zeros_like(t)
    for k in range(1, t.size):
        t0, z0 = t[k - 1], z[k - 1]
        k1 = zdot(t0, z0)
        k2 = zdot(t0 + h / 2, z0 + h / 2 * k1)
        k3 = zdot(t0 + h / 2, z0 + h / 2 * k2)
        k4 = zdot(t0 + h, z0 + h * k3)
        z[k] = z0 + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    want = _dahl_loop(A * np.sin(w * t), x_c)
    assert np.max(np.abs(z - want)) < 1e-4
    up, down = z[(t > 0.2) & (np.abs(np.sin(w * t)) < 1e-3) & (np.cos(w * t) > 0)], \
        z[(t > 0.2) & (np.abs(np.sin(w * t)) < 1e-3) & (np.cos(w * t) < 0)]
    assert up.min() > 0.99 and down.max() < -0.99       # sliding up: z -> 1, down: -1 (friction -c*z opposes v)


def test_dahl_friction_holds_the_diaphragm_where_it_stops():
    """Step on, step off (V = 0 after 0.2 s): without friction the diaphragm returns to x = 0; with Dahl
    friction c it stops where the spring force is balanced by the friction, 0 < (K1*x^2 + K2)*x <= c (hand
    bound), and harness.sim and the FMU agree on where."""
    p = _base(0.3)
    q = p.with_(c_dahl_friction=0.2 * p.C * p.r0 / 0.1, tau_dahl=2e-5)
    dt, t_end = 1e-3, 0.6
    V = np.where(np.arange(int(round(t_end / dt))) < 200, V_STEP, 0.0)    # held over each sample period
    runs = Runs(params={k: np.array([getattr(r, k) for r in (p, q)], dtype=float) for k in PARAM_FIELDS},
                blocked=np.zeros(2, bool), V=np.stack([V, V]), dt=dt)
    res = simulate(runs, Schedule(t_end=t_end, fine_s=t_end))
    x_free, x_held = res.x[0, -1], res.x[1, -1]
    assert abs(x_free) < 1e-3 * p.r0
    spring = (q.K1 * x_held ** 2 + q.K2) * x_held
    assert 0.05 * q.c_dahl_friction < spring <= q.c_dahl_friction * (1 + 1e-9), (spring, q.c_dahl_friction)
    fmu = fmu_simulate(q, res.t, np.append(V, 0.0), rtol=1e-10)
    assert abs(np.asarray(fmu["x_sensor"])[-1] - x_held) < 1e-4 * q.r0


def test_stiff_dahl_lag_follows_the_reference():
    """A presliding length of 1 um (the discovery library's stiffest, ``LENGTH_RANGE_M``): the Dahl state's rate
    |v|/x_c reaches ~1e4/s in this step, and the run's sub-steps follow the speed it reaches (``core.OWN_H_RATE``);
    harness.sim still follows the reference ODE (LSODA, stiff-capable) and the FMU's integrator."""
    p = _base().with_(c_dahl_friction=0.05 * TERMS["dahl_friction"].scale(_base()), tau_dahl=1e-6)
    res = _sim([p])
    I_ref, x_ref = _reference(p, res.t)
    ex = np.max(np.abs(res.x[0] - x_ref)) / np.max(np.abs(x_ref))
    eI = np.max(np.abs(res.I[0] - I_ref)) / np.max(np.abs(I_ref))
    assert ex < 5e-5 and eI < 5e-5, (ex, eI)
    assert physics.own_rate_per_speed(physics.constants(Runs(
        params={k: np.array([getattr(p, k)]) for k in PARAM_FIELDS}, blocked=np.array([False]),
        V=np.array([V_STEP])))) == pytest.approx([1e6])        # |dz'/dz| per unit speed: 1/x_c


def test_a_dahl_run_does_not_change_the_other_runs_of_its_batch():
    """Runs whose sub-steps are fixed (stiff springs: many sub-steps, settled and frozen early) give bit-identical
    outputs and output times whether or not a soft run with a Dahl lag (few sub-steps, speed-sized, never frozen)
    shares their batch: the output times come from the runs of fixed sub-steps."""
    stiff = [BASE.with_(K2=BASE.K2 * f, c_remanence=0.2 * BASE.r0 * BASE.K2 * f / (V_STEP / BASE.R)) for f in (30.0, 60.0)]
    soft = _base().with_(m=BASE.m * 20.0, c_dahl_friction=0.05 * TERMS["dahl_friction"].scale(_base()), tau_dahl=1e-4)

    def run(ps):
        runs = Runs(params={k: np.array([getattr(p, k) for p in ps], dtype=float) for k in PARAM_FIELDS},
                    blocked=np.zeros(len(ps), dtype=bool), V=np.full(len(ps), V_STEP), dt=1e-3)
        return runs, simulate(runs, Schedule(t_end=1.0, fine_s=0.6))

    runs, alone = run(stiff)
    runs2, mixed = run(stiff + [soft])
    c2 = physics.constants(runs2)
    n_sub = physics.substeps(c2, 1e-3)
    assert n_sub[-1] < n_sub[:-1].min()                  # the Dahl run alone would be the first group
    assert np.array_equal(alone.t, mixed.t)
    assert np.array_equal(alone.x, mixed.x[:2]) and np.array_equal(alone.I, mixed.I[:2])
