"""The vectorized effect simulator (harness.sim.simulator) against the FMU's integrator.

Reference: ``fmu_src.model.simulate`` (the FMU's compiled DP5 integrator, events located on its dense
output). Bounds are stated in units of the rig's sensor noise floors sqrt(sigma^2 + q^2/12):
laser 5.03 um, force 0.50 mN, current 2.02 mA. The moved tests of the diagnosis's former RK4 simulator
(harness/sim/rk4.py) keep their assertions on the new API.
"""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from fmu_src.specs import EFFECTS
from fmu_src.terms import LAG_STATES
from fmu_src.model import simulate as fmu_simulate
from harness.data import rig
from harness.sim import core, physics
from harness.sim.settings import Schedule, SimInputError
from harness.sim.simulator import PARAM_FIELDS, Runs, simulate, simulate_by_period

FLOOR_X = 5.03e-6      # laser displacement sensor noise floor [m]
FLOOR_F = 0.50e-3      # force transducer noise floor [N]
FLOOR_I = 2.02e-3      # current sensor noise floor [A]


def _runs(cases, V, dt=1e-3, hold="zoh") -> Runs:
    P = {k: np.array([getattr(c, k) for c in cases], dtype=float) for k in PARAM_FIELDS}
    return Runs(params=P, blocked=np.array([c.blocked for c in cases]), V=V, dt=dt, hold=hold)


def _errors(c, ref, I, y, sel=slice(None)):
    """(max reading error, max current error) in noise floors."""
    yr = ref["F_sensor"] if c.blocked else ref["x_sensor"]
    floor = FLOOR_F if c.blocked else FLOOR_X
    return np.max(np.abs(yr[sel] - y)) / floor, np.max(np.abs(ref["I"][sel] - I)) / FLOOR_I


# ----------------------------------------------------------------------------- moved from test_diagnose
def test_batched_simulator_matches_the_model():
    """The vectorized RK4 integrator reproduces fmu_src.model.simulate (the FMU's physics)."""
    base = rig.true_params(20, 45)
    effects = [{}, {"Rth": 8.0, "tau_th": 4.0}, {"ksat": 3.0}, {"Kc": 0.2 * base.K2, "tau_c": 1.0},
               {"K5": 225.0 * base.K1 / base.D ** 2}, {"lam": 0.3}, {"tau_s": 0.005}]
    cases = [base.with_(r0=r0, blocked=b, **e) for e in effects
             for r0, b in ((0.005, False), (0.002, True), (0.003, False), (0.012, False))]
    V0 = 0.23 / 0.29 * 15.0
    sim = simulate(_runs(cases, np.full(len(cases), V0)), Schedule(t_end=2.8))
    t = np.arange(3001) * 1e-3
    V = np.where(t >= 0.2 - 1e-12, V0, 0.0)
    idx = np.rint((sim.t + 0.2) / 1e-3).astype(int)
    for i, c in enumerate(cases):
        r = fmu_simulate(c, t, V)
        y = r["F_sensor"] if c.blocked else r["x_sensor"]
        floor = 5e-4 if c.blocked else 5e-6            # sensor noise floors (N, m)
        err = np.abs(y[idx] - sim.y[i]) / floor
        assert err.max() < 0.5 and np.sqrt(np.mean(err ** 2)) < 0.03, (c, err.max())
        assert np.abs(r["I"][idx] - sim.I[i]).max() < 0.01 * 2e-3, c


def _draws(rng, base):
    return {
        "coil_heating": lambda: dict(Rth=rng.uniform(1, 20), tau_th=rng.uniform(0.5, 5)),
        "filler_saturation": lambda: dict(ksat=rng.uniform(0.5, 6)),
        "viscoelastic_creep": lambda: dict(Kc=rng.uniform(0.05, 0.5) * base.K2, tau_c=rng.uniform(0.2, 3)),
        "edge_stiffening": lambda: dict(K5=rng.uniform(50, 500) * base.K1 / base.D ** 2),
        "motional_emf": lambda: dict(lam=rng.uniform(0.05, 0.6)),
        "sensor_lag": lambda: dict(tau_s=rng.uniform(0.001, 0.01)),
    }


def test_core_rhs_equals_the_fmu_rhs_for_every_effect_combination():
    """The compiled core's right-hand side, magnetic force and net contact force equal those of
    fmu_src.model.EffectDynamics (the FMU's scalar model) at random states and parameters, for each of
    the 64 combinations of effects (a batch per combination) and for all of them in one mixed batch."""
    from fmu_src.model import EffectDynamics
    from fmu_src.model import FREE
    rng = np.random.default_rng(5)
    base = rig.true_params(20, 45)
    draw = _draws(rng, base)
    names = list(EFFECTS)
    assert list(draw) == names

    def check(cases):
        n = len(cases)
        r0 = np.array([p.r0 for p in cases])
        I, V, v = rng.uniform(-0.2, 1.0, n), rng.uniform(0, 15, n), rng.uniform(-0.4, 0.4, n)
        x = r0 * rng.uniform(-0.5, 0.98, n)
        dT = np.array([rng.uniform(0, 80) if p.Rth > 0 else 0.0 for p in cases])   # 0 where heating is off
        xc = r0 * rng.uniform(-0.5, 1.0, n)
        c = physics.constants(_runs(cases, V))
        state = {"I": I, "x": x, "v": v, "dT": dT, "xc": xc}
        state.update({z: np.zeros(n) for z in LAG_STATES})   # the term set's lag states (its terms off here)
        assert set(core.Y_STATES) == set(state)          # the core's RK4 state: every state but the lag's
        out = core.rhs(physics.param_blocks(c), c["kt"].coef,
                       np.column_stack([state[k] for k in core.Y_STATES] + [np.ones(n)]), V)
        col = {k: i for i, k in enumerate(core.Y_STATES + ("F", "net"))}
        got = out[:, [col[k] for k in ("I", "x", "v", "dT", "xc", "F", "net")]]
        want = np.zeros((n, 7))
        for i, p in enumerate(cases):
            dyn = EffectDynamics(p)
            y = [I[i], x[i], v[i]] + [dT[i]] * dyn.heat + [xc[i]] * dyn.creep + [0.3 * x[i], 0.1] * dyn.lag
            d = dyn.rhs(y, V[i], FREE)
            assert d[1] == v[i] == got[i, 1]
            want[i, 0], want[i, 2] = d[0], d[2]
            want[i, 3] = d[dyn.iT] if dyn.heat else 0.0
            want[i, 4] = d[dyn.ixc] if dyn.creep else 0.0
            want[i, 5] = dyn.magnetic_force(y, p.r0 - x[i])
            want[i, 6] = dyn.net_contact_force(y)
        for k in (0, 2, 3, 4, 5, 6):
            tol = 1e-12 * max(np.max(np.abs(want[:, k])), 1e-30)
            assert np.allclose(got[:, k], want[:, k], rtol=1e-12, atol=tol), (k, np.max(np.abs(got[:, k] - want[:, k])))

    everything = []
    for bits in itertools.product((False, True), repeat=len(names)):
        cases = []
        for _ in range(3):
            kw = {}
            for name, on in zip(names, bits):
                if on:
                    kw.update(draw[name]())
            cases.append(base.with_(r0=float(rng.uniform(0.002, 0.015)), **kw))
        check(cases)
        everything += cases
    check(everything)        # every combination in one batch


def test_simulator_takes_its_physics_from_fmu_src():
    """One implementation of the physics: the core calls the FMU integrator's compiled functions, made from
    fmu_src.effects' and fmu_src.field's function objects (no copy of an equation); and it handles
    contact and the blocked mode on them."""
    from fmu_src import effects as fx, field
    from fmu_src.integrator import COMPILED_PHYSICS
    sources = {"rates": fx.rates, "force": fx.force, "contact_force": fx.contact_force,
               "kernel_value": field.kernel_value, "sensor_readings": fx.sensor_readings}
    assert set(core.PHYSICS) == set(sources)
    for name, f in core.PHYSICS.items():
        # compiled (inlined into the core's loop) from the very function objects the FMU's integrator compiles
        assert f.py_func is sources[name] is COMPILED_PHYSICS[name].py_func, name
    base = rig.true_params(20, 45)
    kw = dict(Rth=8.0, tau_th=4.0, ksat=3.0, Kc=0.2 * base.K2, tau_c=1.0, K5=225.0 * base.K1 / base.D ** 2,
              lam=0.3, tau_s=0.005)
    cases = [base.with_(r0=0.002, **kw), base.with_(r0=0.002, blocked=True, **kw), base.with_(r0=0.009, **kw)]
    V = np.full(3, 0.23 / base.kB * base.R)
    sim = simulate(_runs(cases, V), Schedule(t_end=0.3, fine_s=0.3))
    assert sim.y[0, -1] == pytest.approx(0.002)               # pulled in: contact handled
    assert sim.contact[0, -1] and not sim.contact[1].any() and not sim.contact[2].any()
    assert sim.y[1, -1] > 0.1 and np.all(sim.x[1] == 0.0)    # blocked: a force, no motion


# ----------------------------------------------------------------------------- against the FMU's integrator
def _voltage(rng, kind, t, V0):
    """A random input on the grid t: step, sine or pulse train of amplitude ~V0 [V]."""
    on = rng.uniform(0.02, 0.2)
    if kind == "step":
        return np.where(t >= on, V0 * rng.uniform(0.3, 1.2), 0.0)
    if kind == "sine":
        f = rng.uniform(2.0, 40.0)
        return np.where(t >= on, 0.5 * V0 * rng.uniform(0.5, 1.2) * (1 - np.cos(2 * np.pi * f * (t - on))), 0.0)
    period = rng.uniform(0.08, 0.4)
    duty = rng.uniform(0.3, 0.7)
    return np.where((t >= on) & (((t - on) % period) < duty * period), V0 * rng.uniform(0.5, 1.3), 0.0)


def _random_case(rng, base_samples):
    w, d = base_samples[rng.integers(len(base_samples))]
    p = rig.true_params(w, d)
    kw = {}
    for name, f in _draws(rng, p).items():
        if rng.random() < 0.5:
            kw.update(f())
    return p.with_(r0=float(rng.uniform(0.002, 0.012)), blocked=bool(rng.random() < 0.2), **kw)


@pytest.mark.parametrize("seed", [11, 12])
def test_random_runs_with_effects_match_the_fmu(seed):
    """Random samples, gaps, effect combinations (each effect on with probability 1/2), blocked or free,
    under random steps, sines and pulse trains (zero-order hold, 1 kHz): the reading within 0.1 noise
    floors and the current within 0.05 noise floors of the FMU's integrator (rtol 1e-9) at every sample."""
    rng = np.random.default_rng(seed)
    t = np.arange(1001) * 1e-3
    cases, Vs = [], []
    for i in range(12):
        c = _random_case(rng, rig.TRAINING_SAMPLES)
        V0 = 0.23 / c.kB * c.R
        cases.append(c)
        Vs.append(_voltage(rng, ("step", "sine", "pulse")[i % 3], t, V0))
    sim = simulate(_runs(cases, np.array(Vs)[:, :-1]))
    assert np.allclose(sim.t, t)
    for i, c in enumerate(cases):
        ref = fmu_simulate(c, t, Vs[i], rtol=1e-9)
        ey, eI = _errors(c, ref, sim.I[i], sim.y[i])
        assert ey < 0.1 and eI < 0.05, (i, c, ey, eI)


def test_contact_impact_rest_release_and_blocked():
    """Impact on the coil face, resting, release after the pulse, a bounce-free pull-in under a ramp,
    and the blocked mode: readings within 0.1 noise floors, current within 0.05, the contact flag equal to
    the FMU's except within one sample of each impact or release."""
    base = rig.true_params(20, 45)
    t = np.arange(1501) * 1e-3
    V0 = 0.23 / base.kB * base.R
    pulse = np.where((t >= 0.1) & (t < 0.8), V0, 0.0)
    ramp = np.clip((t - 0.1) / 0.8, 0.0, 1.0) * V0
    cases = [base.with_(r0=0.003), base.with_(r0=0.002, Kc=0.2 * base.K2, tau_c=0.3),
             base.with_(r0=0.003, lam=0.4, tau_s=0.004), base.with_(r0=0.002, blocked=True, Rth=8.0, tau_th=1.0),
             base.with_(r0=0.003, ksat=2.0, K5=225.0 * base.K1 / base.D ** 2)]
    Vs = np.array([pulse, pulse, ramp, pulse, pulse])
    sim = simulate(_runs(cases, Vs[:, :-1]))
    n_events = 0
    for i, c in enumerate(cases):
        ref = fmu_simulate(c, t, Vs[i], rtol=1e-9)
        ey, eI = _errors(c, ref, sim.I[i], sim.y[i])
        assert ey < 0.1 and eI < 0.05, (i, c, ey, eI)
        flips = np.flatnonzero(np.diff(ref["contact"].astype(int)))
        n_events += flips.size
        bad = np.flatnonzero(ref["contact"] != sim.contact[i])
        assert all(np.min(np.abs(flips + 0.5 - b)) <= 1.5 for b in bad), (i, bad, flips)
        if c.blocked:
            assert not sim.contact[i].any() and np.all(ref["x"] == 0.0)
    assert n_events >= 5          # impacts (3) and releases (2) did happen


def test_per_run_sample_periods():
    """Sample periods of other rigs (200 Hz, 1 kHz, 10 kHz) in one call: each run on its own grid,
    matching the FMU there."""
    base = rig.true_params(30, 60)
    cases, Vs, dts = [], [], []
    for dt, r0 in ((5e-3, 0.005), (1e-3, 0.003), (1e-4, 0.009)):
        cases.append(base.with_(r0=r0, tau_s=0.003))
        dts.append(dt)
        Vs.append(0.2 / base.kB * base.R)
    runs = _runs(cases, np.array(Vs), dt=np.array(dts))
    with pytest.raises(SimInputError):
        simulate(runs)
    sch = Schedule(t_end=0.6, fine_s=0.6)
    parts = simulate_by_period(runs, sch)
    assert len(parts) == 3
    for idx, sim in parts:
        (i,) = idx
        dt = dts[i]
        assert np.allclose(np.diff(sim.t), dt)
        t = np.concatenate([[0.0], 0.05 + sim.t])         # 50 ms at rest before the onset
        V = np.where(t >= 0.05 - 1e-12, Vs[i], 0.0)
        ref = fmu_simulate(cases[i], t, V, rtol=1e-9)
        ey, eI = _errors(cases[i], ref, sim.I[0], sim.y[0], sel=slice(1, None))
        assert ey < 0.1 and eI < 0.05, (dt, ey, eI)


def test_linear_hold_matches_a_fine_zero_order_hold():
    """A voltage linear between the samples equals the FMU's zero-order hold on a grid 20 times finer
    (voltage at the fine intervals' midpoints: second-order accurate) to 0.1 noise floors."""
    base = rig.true_params(20, 45)
    cases = [base.with_(r0=0.005, lam=0.3), base.with_(r0=0.002, blocked=True, ksat=2.0)]
    t = np.arange(401) * 1e-3
    V0 = 0.23 / base.kB * base.R
    V = V0 * np.clip(np.sin(2 * np.pi * 7.0 * t), 0.0, None)
    sim = simulate(_runs(cases, np.array([V, V]), hold="linear"))
    tf = np.arange(20 * 400 + 1) * 5e-5
    Vf = np.interp(tf + 2.5e-5, t, V)
    for i, c in enumerate(cases):
        ref = fmu_simulate(c, tf, Vf, rtol=1e-9)
        ref = {k: ref[k][::20] for k in ("I", "x_sensor", "F_sensor")}
        ey, eI = _errors(c, ref, sim.I[i], sim.y[i])
        assert ey < 0.1 and eI < 0.05, (i, ey, eI)


def test_a_run_does_not_depend_on_its_batch():
    """Runs with different sub-step counts, slow states and frozen (settled) runs in one batch: each run's
    outputs equal, bit for bit, those of the same run simulated alone (constant input: fine, coarse and
    tail parts; and a zero-order-hold input)."""
    base = rig.true_params(20, 45)
    cases = [base.with_(r0=0.009), base.with_(r0=0.002, blocked=True, tau_s=0.004),
             base.with_(r0=0.003, m=0.0005, C=0.05), base.with_(r0=0.005, Rth=8.0, tau_th=2.0),
             base.with_(r0=0.004, Kc=0.2 * base.K2, tau_c=0.5, lam=0.3)]
    V = np.full(len(cases), 0.2 / base.kB * base.R)
    runs = _runs(cases, V)
    assert np.unique(physics.substeps(physics.constants(runs), 1e-3)).size > 1
    sch = Schedule(t_end=1.2, fine_s=0.4)
    t = np.arange(801) * 1e-3
    Vz = np.array([np.where((t >= 0.05) & (t < 0.5), v, 0.0) for v in V])[:, :-1]
    together = simulate(runs, sch), simulate(_runs(cases, Vz))
    for i in range(len(cases)):
        alone = simulate(_runs(cases[i:i + 1], V[i:i + 1]), sch), simulate(_runs(cases[i:i + 1], Vz[i:i + 1]))
        for both, one in zip(together, alone):
            # the output times to rounding (a running sum, or one product once every run has settled)
            assert np.allclose(both.t, one.t, rtol=0.0, atol=1e-12)
            for k in ("I", "x", "F", "contact"):
                assert np.array_equal(getattr(both, k)[i], getattr(one, k)[0]), (i, k)


def test_bad_runs():
    base = rig.true_params(20, 45)
    good = _runs([base], np.array([5.0]))
    with pytest.raises(SimInputError, match="lacks"):
        Runs(params={"R": np.array([1.0])}, blocked=np.array([False]), V=np.array([1.0]))
    with pytest.raises(SimInputError, match="hold"):
        Runs(params=good.params, blocked=good.blocked, V=good.V, hold="cubic")
    with pytest.raises(SimInputError, match="dt"):
        Runs(params=good.params, blocked=good.blocked, V=good.V, dt=0.0)
    with pytest.raises(SimInputError, match="shape"):
        Runs(params=good.params, blocked=good.blocked, V=np.ones((2, 3)))
