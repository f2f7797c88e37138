"""harness.control.estimator: the EKF on the compiled model estimates the true states of a simulated plant.

The plant is the FMU's model (``fmu_src.model.ActuatorModel`` at a tight tolerance, stepped on its own) with the
catalogue effects drawn by the property tests; its readings are the true x_sensor and I plus white Gaussian noise
at the virtual rig's noise floors times a factor (1x-5x). Checks, against the plant's true states:

* error bound: after a 0.3 s start-up, the RMS error of the displacement read (x, or x_sensor with the
  sensor_lag effect) is below the displacement noise sigma_x (the filter averages), of x below 2 sigma_x, of v below half the noise of the readings' own difference quotient sqrt(2)*sigma_x/dt (what a
  numerical derivative of the readings gives), and of every state below 4 of the filter's own standard
  deviations 99 % of the time;
* consistency: on a plant with the process noise the filter assumes (kicks of covariance Qc*dt each period) and
  an initial state drawn from the filter's initial distribution, the normalized estimation error squared averaged
  over a Monte Carlo of M runs lies in its two-sided 99.9 % chi-square band (scipy.stats.chi2, M*n degrees of
  freedom over M, n states) at three separated steps (10, the middle, the last).

Fast profile by default, deep profile under ``-m deep``.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from fmu_src.model import ActuatorModel
from fmu_src.specs import EFFECTS, Params
from harness.control.estimator import Ekf, EkfSettings, EstimatorError, NoiseLevels, filter_record, nees
from harness.data import rig

_COMMON = dict(deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
FAST = settings(max_examples=4, derandomize=True, phases=[Phase.explicit, Phase.generate], **_COMMON)
DEEP = settings(max_examples=60, **_COMMON)
DT = 0.01


def _voltage(t):
    """A drive that moves the diaphragm over most of its range: a 2 Hz sine on an offset, a step at 1 s."""
    return 10.0 + 6.0 * np.sin(2 * np.pi * 2.0 * t) + 3.0 * (t > 1.0)


def _run(p, noise, rng, n_steps, kicks=None, ekf_settings=None):
    """Plant and EKF side by side; returns (errors, filter std, NEES) per step after the update."""
    plant = ActuatorModel(p, rtol=1e-10)
    plant.reset(0.0)
    ekf = Ekf(p, noise, ekf_settings or EkfSettings(dt_s=DT))
    n = ekf.n_y
    if kicks is not None:   # the true initial state drawn from the filter's initial distribution
        y0 = rng.multivariate_normal(ekf.model_state, ekf.P[:n, :n])
        y0[1] = min(y0[1], p.r0 * 0.999)
        plant.integ.reset(0.0, y0)
    errs, sds, ne = np.empty((n_steps, n)), np.empty((n_steps, n)), np.empty(n_steps)
    t = np.arange(n_steps) * DT
    V = _voltage(t)
    for k in range(n_steps):
        o = plant.outputs()
        z = [o["x_sensor"] + rng.normal(0, noise.sigma_x_m), o["I"] + rng.normal(0, noise.sigma_I_A)]
        ekf.update(z)
        y = np.array(plant.integ.y)
        errs[k] = ekf.model_state - y
        sds[k] = ekf.std()[:n]
        ne[k] = nees(errs[k], ekf.P[:n, :n])
        ekf.predict(V[k])
        plant.advance(t[k] + DT, V[k])
        if kicks is not None:   # the process noise the filter assumes, as kicks at the period's end
            y = np.array(plant.integ.y) + rng.multivariate_normal(np.zeros(n), kicks)
            y[1] = min(y[1], p.r0 * 0.999)
            plant.integ.reset(t[k] + DT, y)
    return errs, sds, ne



effect_sets = st.lists(st.sampled_from(sorted(EFFECTS)), max_size=3, unique=True)


def _check_error_bounds(effects, factor, seed):
    p = rig.apply_effects(Params(), {e: 1.0 for e in effects})
    noise = NoiseLevels.from_rig().scaled(factor)
    errs, sds, _ = _run(p, noise, np.random.default_rng(seed), 150)
    e, s = errs[30:], sds[30:]
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    names = Ekf(p, noise).names
    read = names.index("x_sensor") if "x_sensor" in names else 1
    assert rms[read] < noise.sigma_x_m, f"x read RMS error {rms[read]:.3g} m vs sigma_x {noise.sigma_x_m:.3g} m"
    assert rms[1] < 2 * noise.sigma_x_m, f"x RMS error {rms[1]:.3g} m vs sigma_x {noise.sigma_x_m:.3g} m"
    v_diff = np.sqrt(2) * noise.sigma_x_m / DT
    assert rms[2] < 0.5 * v_diff, f"v RMS error {rms[2]:.3g} m/s vs difference quotient noise {v_diff:.3g}"
    inside = np.mean(np.abs(e) <= 4 * s, axis=0)
    assert np.all(inside >= 0.99), dict(zip(names, inside))


@FAST
@given(effects=effect_sets, factor=st.floats(1.0, 5.0), seed=st.integers(0, 2 ** 16))
def test_estimation_error_within_bounds(effects, factor, seed):
    _check_error_bounds(effects, factor, seed)


@pytest.mark.deep
@DEEP
@given(effects=effect_sets, factor=st.floats(1.0, 5.0), seed=st.integers(0, 2 ** 32 - 1))
def test_estimation_error_within_bounds_deep(effects, factor, seed):
    _check_error_bounds(effects, factor, seed)


def _check_consistency(effects, factor, seed, runs=25, n_steps=40):
    p = rig.apply_effects(Params(), {e: 1.0 for e in effects})
    noise = NoiseLevels.from_rig().scaled(factor)
    s = EkfSettings(dt_s=DT)
    ekf = Ekf(p, noise, s)
    kicks = ekf.Qc * DT
    rng = np.random.default_rng(seed)
    ne = np.array([_run(p, noise, rng, n_steps, kicks, s)[2] for _ in range(runs)])
    n = ekf.n_y
    mean_t = ne.mean(axis=0)   # Monte Carlo mean per time step: chi2(runs*n)/runs for a consistent filter
    lo, hi = chi2.ppf(0.0005, runs * n) / runs, chi2.ppf(0.9995, runs * n) / runs
    # three separated steps (the steps of one run are correlated: a weakly observable state, e.g. the winding
    # temperature, keeps its initial error for seconds, so a fraction of all steps is not a test of many samples)
    for k in (10, n_steps // 2, n_steps - 1):
        assert lo <= mean_t[k] <= hi, f"step {k}: MC-mean NEES {mean_t[k]:.2f} outside [{lo:.2f}, {hi:.2f}] ({n} states)"


@FAST
@given(effects=effect_sets, factor=st.floats(1.0, 5.0), seed=st.integers(0, 2 ** 16))
def test_nees_within_chi_square_band(effects, factor, seed):
    _check_consistency(effects, factor, seed)


@pytest.mark.deep
@DEEP
@given(effects=effect_sets, factor=st.floats(1.0, 5.0), seed=st.integers(0, 2 ** 32 - 1))
def test_nees_within_chi_square_band_deep(effects, factor, seed):
    _check_consistency(effects, factor, seed, runs=50, n_steps=60)


def test_filter_record_velocity_of_a_free_oscillation():
    """Independent check of the velocity: a step response of the plain model, whose velocity is the derivative of
    its displacement (numpy.gradient of the true x on a fine grid), filtered from noisy readings at 1 kHz."""
    p = Params()
    plant = ActuatorModel(p, rtol=1e-10)
    t = np.arange(0.0, 0.6, 1e-3)
    V = np.where(t > 0.05, 12.0, 0.0)
    x, I = np.empty(t.size), np.empty(t.size)
    for k in range(t.size):
        o = plant.outputs()
        x[k], I[k] = o["x"], o["I"]
        if k + 1 < t.size:
            plant.advance(t[k + 1], V[k])
    v_true = np.gradient(x, t)
    rng = np.random.default_rng(3)
    noise = NoiseLevels.from_rig()
    z = np.column_stack([x + rng.normal(0, noise.sigma_x_m, t.size), I + rng.normal(0, noise.sigma_I_A, t.size)])
    out = filter_record(p, t, V, z, noise)
    v_est = out["x"][:, out["names"].index("v")]
    err = v_est[100:] - v_true[100:]
    assert np.sqrt(np.mean(err ** 2)) < 0.05 * np.max(np.abs(v_true)), np.sqrt(np.mean(err ** 2))


@pytest.mark.parametrize("kw, msg", [(dict(sigma_x_m=0.0, sigma_I_A=1e-3), "sigma_x_m"),
                                     (dict(sigma_x_m=1e-6, sigma_I_A=float("nan")), "sigma_I_A")])
def test_noise_levels_checked(kw, msg):
    with pytest.raises(EstimatorError, match=msg):
        NoiseLevels(**kw)


def test_bad_measurement_refused():
    ekf = Ekf(Params(), NoiseLevels.from_rig())
    with pytest.raises(EstimatorError, match="measurement"):
        ekf.update([1e-3])


def test_force_readings_are_used():
    """Where the rig also reads the force (F_sensor), the filter takes it as a third reading. With a poor laser
    (20x the displacement noise floor) the force, which depends on x through the kernel, narrows the estimate of x:
    on the same readings the filter with the force has a smaller variance of x at every step (at least 3 % smaller
    on average) and an x error within the laser's noise."""
    p = Params()
    base = NoiseLevels.from_rig()
    noise = NoiseLevels(20 * base.sigma_x_m, base.sigma_I_A)
    noise_f = NoiseLevels(noise.sigma_x_m, noise.sigma_I_A, rig.FORCE.noise_floor)
    plant = ActuatorModel(p, rtol=1e-10)
    with_f, without = Ekf(p, noise_f), Ekf(p, noise)
    rng = np.random.default_rng(5)
    t = np.arange(100) * DT
    V = _voltage(t)
    errs, ratio = [], []
    for k in range(t.size):
        o = plant.outputs()
        z = [o["x_sensor"] + rng.normal(0, noise.sigma_x_m), o["I"] + rng.normal(0, noise.sigma_I_A)]
        with_f.update(z + [o["F_sensor"] + rng.normal(0, noise_f.sigma_F_N)])
        without.update(z)
        errs.append(with_f.model_state - np.array(plant.integ.y))
        ratio.append(with_f.P[1, 1] / without.P[1, 1])
        for f in (with_f, without):
            f.predict(V[k])
        plant.advance(t[k] + DT, V[k])
    e = np.array(errs)[30:]
    assert np.sqrt(np.mean(e[:, 1] ** 2)) < noise.sigma_x_m
    assert max(ratio[30:]) <= 1.0 + 1e-6 and np.mean(ratio[30:]) < 0.97, (min(ratio), np.mean(ratio[30:]))
