"""Population runs of the identification (harness.sim.population, on the simulator's compiled core) against
the FMU's scalar model (fmu_src.model.simulate) and against the simulator's own constant-free runs."""
import dataclasses
import math

import numpy as np
import pytest

from harness.sim import physics, population
from harness.sim.simulator import PARAM_FIELDS, Runs, simulate as simulate_batch
from harness.sim.settings import MechParams, PopulationSettings, SimInputError
from fmu_src.coil import voltage_for_field
from fmu_src.field import make_kernel
from fmu_src.model import simulate
from harness.data import rig
from harness.data import protocol

T = protocol.time_grid(protocol.PRE_STEP_S + protocol.STEP_POST_S)


def _prep(p, V, **kw):
    return population.prepare_test(T, V, MechParams.of(p), **kw)


def _rel_err(x, ref):
    return float(np.max(np.abs(x - ref)) / np.max(np.abs(ref)))


def _voltage(p, kind):
    V0 = voltage_for_field(0.23, p.kB, p.R)
    if kind == "step":
        return protocol.step_voltage(T, V0)
    if kind == "step_T3":
        return protocol.step_voltage(T, voltage_for_field(0.11, p.kB, p.R))
    if kind == "pulse":      # on at 0.2 s, off at 1.0 s: release from the coil face
        return np.where((T >= protocol.PRE_STEP_S - 1e-12) & (T < 1.0), V0, 0.0)
    raise ValueError(kind)


def test_zoh_current_is_exact_rl_solution():
    R, L = 15.0, 0.12
    V = np.where(T >= 0.2 - 1e-12, 12.0, 0.0)
    I = population.zoh_current(T, V, R, L)
    t_on = T - 0.2
    exact = np.where(T > 0.2, 12.0 / R * (1.0 - np.exp(-np.clip(t_on, 0, None) * R / L)), 0.0)
    assert np.max(np.abs(I - exact)) < 1e-12
    ref = simulate(rig.true_params(20, 45), T, V, rtol=1e-10)["I"]
    assert np.max(np.abs(I - ref)) < 1e-9


def test_zoh_current_from_a_nonzero_initial_current():
    """I0 != 0 (a current already flowing at the first sample): the exact RL solution written by hand,
    I(t) = V/R + (I0 - V/R) exp(-t R/L) under a constant V, then the decay I(t1) exp(-(t - t1) R/L) after
    switch-off at t1, on a uniform grid (lfilter path) and on a non-uniform one (loop path)."""
    R, L, I0, V0, t1 = 15.0, 0.12, 0.5, 3.0, 0.05
    for t in (np.arange(101) * 1e-3, np.cumsum(np.r_[0.0, np.full(100, 1e-3) * (1 + 0.3 * np.sin(np.arange(100)))])):
        V = np.where(t < t1 - 1e-12, V0, 0.0)
        I = population.zoh_current(t, V, R, L, I0)
        k1 = int(np.flatnonzero(t >= t1 - 1e-12)[0])        # first sample with V = 0
        on = V0 / R + (I0 - V0 / R) * np.exp(-t * R / L)
        exact = np.where(np.arange(t.size) <= k1, on, on[k1] * np.exp(-(t - t[k1]) * R / L))
        assert I[0] == I0
        assert np.max(np.abs(I - exact)) < 1e-12, np.max(np.abs(I - exact))


def test_population_runs_are_the_simulators_runs():
    """One simulator: a population run without settle truncation is the simulator's zero-order-hold run of
    the same parameters (same core, same RK4 sub-steps), up to the current, which the population prescribes
    by the exact RL solution where the simulator integrates it by RK4 (differences ~ (h R/L)^5)."""
    p = rig.true_params(20, 45).with_(r0=0.005)
    V = _voltage(p, "step")
    mt = _prep(p, V)
    C = p.C * np.array([1.0, 0.3, 2.0])
    m = p.m * np.array([1.0, 1.0, 0.5])
    prm = {k: np.full(3, float(getattr(p, k))) for k in PARAM_FIELDS}
    prm["C"], prm["m"] = C, m
    runs = Runs(params=prm, blocked=np.zeros(3, dtype=bool), V=np.tile(V[:-1], (3, 1)), dt=T[1] - T[0])
    sim = simulate_batch(runs)
    n_sub = physics.substeps(physics.constants(runs), T[1] - T[0])      # the simulator's sub-steps
    pop = population.integrate_one(mt, C, m, PopulationSettings(settle_rtol=0.0, substeps=n_sub)).full()
    assert sim.x.shape == pop.shape
    err = np.max(np.abs(sim.x - pop)) / np.max(np.abs(pop))
    assert 0.0 < err < 5e-6, err


# (wt%, D mm, gap mm, voltage): free steps at the rig's gaps, snap to the coil face, release
CASES = [
    (10, 30, 3.0, "step"), (20, 45, 5.0, "step"), (20, 45, 5.0, "step_T3"), (30, 60, 9.0, "step"),
    (20, 45, 3.0, "step"), (30, 60, 7.0, "step"),          # contact (impact, stays)
    (20, 45, 3.0, "pulse"), (10, 30, 1.0, "pulse"),       # contact then release / free pulse
]


@pytest.mark.parametrize("w,d,gap,kind", CASES)
def test_agrees_with_scalar_model(w, d, gap, kind):
    p = rig.true_params(w, d).with_(r0=gap / 1000.0)
    V = _voltage(p, kind)
    mt = _prep(p, V)
    # the true candidate and two others (less damped, heavier) in one batch
    C = np.array([p.C, 0.3 * p.C, p.C])
    m = np.array([p.m, p.m, 2.0 * p.m])
    res = population.integrate_one(mt, C, m)
    X = res.full()
    for j in range(3):
        ref = simulate(p.with_(C=float(C[j]), m=float(m[j])), T, V, rtol=1e-10)
        assert _rel_err(X[j], ref["x"]) < 1e-4, (j, _rel_err(X[j], ref["x"]))
    contact = simulate(p, T, V, rtol=1e-10)["contact"].any()
    assert contact == (kind == "pulse" and w == 20 or (w, gap) in ((20, 3.0), (30, 7.0)))


def test_settle_fill_equals_full_integration():
    p = rig.true_params(20, 45).with_(r0=0.005)
    mt = _prep(p, _voltage(p, "step"))
    C = p.C * np.array([0.5, 1.0, 2.0])
    m = p.m * np.array([1.0, 0.7, 1.5])
    fast = population.integrate_one(mt, C, m)
    slow = population.integrate_one(mt, C, m, PopulationSettings(settle_rtol=0.0))
    assert fast.settled.all() and not slow.settled.any()
    assert fast.candidate_steps < 0.3 * slow.candidate_steps
    # the lightly damped candidate leaves through the closed-form linear tail (settled later than the
    # last integrated sample), the settle test alone would integrate it further
    no_tail = population.integrate_one(mt, C, m, PopulationSettings(linear_tail=False))
    assert fast.candidate_steps < no_tail.candidate_steps
    Xs = slow.full()
    assert np.max(np.abs(no_tail.full() - Xs)) < 2e-5 * np.max(np.abs(Xs))
    Xf = fast.full()
    assert np.max(np.abs(Xf - Xs)) < 2e-5 * np.max(np.abs(Xs))
    # the fill value is the static equilibrium at the final current
    assert np.allclose(fast.x_fill, mt.eq_x[0], rtol=1e-12)


def test_candidate_does_not_depend_on_the_batch():
    p = rig.true_params(20, 45).with_(r0=0.005)
    q = rig.true_params(30, 60).with_(r0=0.009)
    a = _prep(p, _voltage(p, "step"))
    b = _prep(q, _voltage(q, "step_T3"))
    alone = population.integrate_one(a, [p.C], [p.m]).full()[0]
    mixed = population.integrate([b, a, b], np.array([0, 1, 2, 1]), np.array([q.C, p.C, 0.5 * q.C, 3 * p.C]),
                            np.array([q.m, p.m, q.m, 0.2 * p.m])).full()[1]
    assert np.array_equal(alone, mixed)
    # records of different lengths in one batch (integrated part by part)
    Vp = _voltage(p, "step")
    short = population.prepare_test(T[:1500], Vp[:1500], MechParams.of(p))
    alone_short = population.integrate_one(short, [0.5 * p.C], [p.m]).full()[0]
    both = population.integrate([short, a], np.array([1, 0, 1]), np.array([p.C, 0.5 * p.C, p.C]),
                                np.array([p.m, p.m, p.m])).full()
    assert np.array_equal(both[0], alone) and np.array_equal(both[2], alone)
    assert np.array_equal(both[1, :1500], alone_short)


def test_result_helpers_match_dense_arrays():
    p = rig.true_params(20, 45).with_(r0=0.005)
    mt = _prep(p, _voltage(p, "step"))
    rng = np.random.default_rng(3)
    fn = 10 ** rng.uniform(0, 2, 40)
    z = 10 ** rng.uniform(-1.3, 0.7, 40)
    m = p.K2 / (2 * np.pi * fn) ** 2
    C = 2 * z * np.sqrt(p.K2 * m)
    res = population.integrate_one(mt, C, m, PopulationSettings(settle_rtol=1e-4))
    X = res.full()
    y = X[7] + 1e-5 * np.sin(T)
    assert np.allclose(res.sum_sq_error(y), ((X - y) ** 2).sum(axis=1), rtol=1e-10, atol=1e-20)
    assert np.allclose(res.tail_mean(301), X[:, -301:].mean(axis=1), rtol=1e-12, atol=1e-18)
    assert np.allclose(res.mean_before(200), X[:, :200].mean(axis=1), atol=1e-18)
    assert np.allclose(res.range_sum(np.arange(40) * 50), [X[j, 50 * j:].sum() for j in range(40)],
                       rtol=1e-12, atol=1e-18)
    k = rng.integers(0, T.size, 40)
    assert np.array_equal(res.values_at(k), X[np.arange(40), k])
    c = X[:, -1]
    tol = 0.02 * np.abs(c)
    last = res.last_outside(c, tol, k_min=200)
    for j in range(40):
        out = np.flatnonzero(np.abs(X[j, 200:] - c[j]) > tol[j])
        assert last[j] == (out[-1] + 200 if out.size else -1)
    assert np.array_equal(res.dense(150, 900), X[:, 150:900].T)


def test_bad_inputs():
    p = rig.true_params(20, 45).with_(r0=0.005)
    V = _voltage(p, "step")
    t_bad = T.copy()
    t_bad[10] += 3e-4
    with pytest.raises(SimInputError, match="uniform"):
        population.prepare_test(t_bad, V, MechParams.of(p))
    with pytest.raises(SimInputError, match="K2"):
        population.prepare_test(T, V, dataclasses.replace(MechParams.of(p), K2=-1.0))
    mt = _prep(p, V)
    with pytest.raises(SimInputError, match="m"):
        population.integrate_one(mt, [p.C], [0.0])
    with pytest.raises(SimInputError, match="C"):
        population.integrate_one(mt, [math.nan], [p.m])


def _between_samples_case(frac: float, rate_hz: float = 136.0, n: int = 300, k0: int = 40, fine: int = 20):
    """A step of the T5 field from rest that begins ``frac`` of a period before sample k0 of a ``rate_hz`` grid:
    (coarse grid, the recorded voltage (zero before k0), the delay [s], the FMU's scalar model on a grid
    ``fine`` times finer that has a sample at the step (so its zero-order hold is the step itself), sampled
    at the coarse instants: the reference)."""
    p = rig.true_params(20, 45).with_(r0=0.004)
    dt = 1.0 / rate_hz
    t = np.arange(n) * dt
    V0 = voltage_for_field(0.23, p.kB, p.R)
    V = np.where(np.arange(n) >= k0, V0, 0.0)
    tf = np.arange((n - 1) * fine + 1) * (dt / fine)
    k_on = k0 * fine - int(round(frac * fine))                  # the step's sample on the fine grid
    Vf = np.where(np.arange(tf.size) >= k_on, V0, 0.0)
    ref = simulate(p, tf, Vf, rtol=1e-11)["x"][::fine]
    return p, t, V, frac * dt, ref


@pytest.mark.parametrize("frac", [0.5, 0.3, 0.85])
def test_step_between_samples_starts_at_its_instant(frac):
    """A step that begins between two samples (a DAQ whose clock is not the drive's) is simulated from its
    instant, at a slow rate: the same as the FMU's scalar model on a grid that has a sample at the step.
    The held voltage that gives the right current at the next sample (the coil-equivalent voltage the
    identification used before) puts the force earlier and misses by far more."""
    p, t, V, d, ref = _between_samples_case(frac)
    mt = population.prepare_test(t, V, MechParams.of(p), onset_delay_s=d)
    x = population.integrate_one(mt, [p.C], p.m, PopulationSettings(settle_rtol=0.0, rk_tol=1e-9)).full()[0]
    err = _rel_err(x, ref)
    assert err < 1e-7, err
    tau = p.L / p.R
    Veq = V.copy()
    Veq[39] = V[40] * math.expm1(-d / tau) / math.expm1(-(t[1] - t[0]) / tau)
    held = population.integrate_one(population.prepare_test(t, Veq, MechParams.of(p)), [p.C], p.m,
                                    PopulationSettings(settle_rtol=0.0, rk_tol=1e-9)).full()[0]
    assert _rel_err(held, ref) > 20 * max(err, 1e-6)
    # the current on the grid is the RL coil's from the instant on
    on = np.clip(t - (t[40] - d), 0.0, None)
    assert np.allclose(mt.I, np.where(on > 0, V[40] / p.R * (1 - np.exp(-on / tau)), 0.0), rtol=0, atol=1e-12)


def test_steps_that_start_in_different_intervals_share_a_batch():
    """Candidates on two tests whose steps begin between samples in different sample intervals, in one
    ``integrate`` call: each as integrated alone (a part per first interval, the later one at rest before;
    in one part the later step's interval would be integrated whole)."""
    p, t, V, d, _ = _between_samples_case(0.4)
    late = np.r_[np.zeros(7), V[:-7]]
    a = population.prepare_test(t, V, MechParams.of(p), onset_delay_s=d)
    b = population.prepare_test(t, late, MechParams.of(p), onset_delay_s=0.7 * (t[1] - t[0]))
    C, m = np.array([p.C, 0.5 * p.C, p.C]), np.array([p.m, p.m, 1.5 * p.m])
    both = population.integrate([a, b], np.array([0, 1, 1]), C, m).full()
    alone_a = population.integrate_one(a, C[:1], m[:1]).full()
    alone_b = population.integrate_one(b, C[1:], m[1:]).full()
    assert np.array_equal(both[:1], alone_a) and np.array_equal(both[1:], alone_b)
    with pytest.raises(SimInputError, match="onset_delay_s needs a step from rest"):
        population.prepare_test(t, V + 0.1, MechParams.of(p), onset_delay_s=d)
