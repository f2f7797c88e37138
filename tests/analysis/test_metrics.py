"""Tests of harness.analysis.core.metrics against hand-computed cases."""
import math

import numpy as np
import pytest

from harness.analysis.core import metrics as M

DT = 1e-3     # 1 kHz sampling [s]
TAU = 0.02    # first-order time constant [s]
TS_FO = TAU * math.log(50.0)  # exact 2 % settling time of 1 - exp(-t/tau) [s]


def first_order(t, tau=TAU):
    return 1.0 - np.exp(-t / tau)


def second_order(t, wn, zeta):
    """Unit step response of wn^2 / (s^2 + 2 zeta wn s + wn^2), zeta < 1."""
    wd = wn * math.sqrt(1.0 - zeta * zeta)
    return 1.0 - np.exp(-zeta * wn * t) * (
        np.cos(wd * t) + zeta / math.sqrt(1.0 - zeta * zeta) * np.sin(wd * t))


# --------------------------------------------------------------------------- rmse
def test_rmse_known_vectors():
    assert M.rmse([1.0, 2.0, 3.0], [1.0, 2.0, 5.0]) == pytest.approx(math.sqrt(4.0 / 3.0))
    assert M.rmse(np.zeros(4), np.array([1.0, -1.0, 1.0, -1.0])) == pytest.approx(1.0)
    assert M.rmse([0.5], [0.5]) == 0.0


@pytest.mark.parametrize(
    "measured, simulated, match",
    [
        ([1.0, 2.0], [1.0, 2.0, 3.0], "measured and simulated differ in shape"),
        ([], [], "measured: empty"),
        ([1.0, 2.0], [1.0, np.nan], "simulated: non-finite"),
        ([np.inf, 2.0], [1.0, 2.0], "measured: non-finite"),
        ([[1.0, 2.0], [3.0, 4.0]], [[1.0, 2.0], [3.0, 4.0]], "measured: expected a 1-D array"),
    ],
)
def test_rmse_errors_name_the_argument(measured, simulated, match):
    with pytest.raises(ValueError, match=match):
        M.rmse(measured, simulated)


# --------------------------------------------------------------------------- settling time
def test_first_order_settling_time_is_tau_ln50():
    t = np.arange(0.0, 0.5, DT)
    ts = M.settling_time(t, first_order(t))  # defaults: y0 = y[0], y_final = tail mean
    assert abs(ts - TS_FO) < DT
    assert abs(ts - TS_FO) < 1e-4  # linear interpolation does much better than one sample


def test_settling_time_scaled_negative_step():
    t = np.arange(0.0, 0.5, DT)
    y = 2.0 - 3.0 * first_order(t)  # from 2 down to -1
    assert abs(M.settling_time(t, y) - TS_FO) < DT
    assert abs(M.settling_time(t, y, y0=2.0, y_final=-1.0) - TS_FO) < 1e-4


def _dense_last_exit(wn, zeta, band=0.02, t_end=1.0):
    """Independent reference: last band exit on a 1 us grid, refined by bisection."""
    td = np.arange(0.0, t_end, 1e-6)
    out = np.abs(second_order(td, wn, zeta) - 1.0) > band
    k = int(np.flatnonzero(out)[-1])
    lo, hi = td[k], td[k + 1]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if abs(second_order(np.array([mid]), wn, zeta)[0] - 1.0) > band:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def test_second_order_underdamped_last_band_exit():
    wn, zeta = 50.0, 0.3
    ref = _dense_last_exit(wn, zeta)
    # the reference must lie past the first overshoot, i.e. the test exercises re-entry
    t_peak = math.pi / (wn * math.sqrt(1 - zeta ** 2))
    assert ref > 2 * t_peak
    t = np.arange(0.0, 2.0, DT)
    y = second_order(t, wn, zeta)
    assert abs(M.settling_time(t, y, y0=0.0, y_final=1.0) - ref) < DT
    assert abs(M.settling_time(t, y) - ref) < DT  # default levels on a settled record


def test_delayed_step_measured_from_t_step():
    t = np.arange(0.0, 1.0, DT)
    t_step = 0.2
    y = np.where(t < t_step, 0.5, 0.5 + 2.0 * first_order(t - t_step))
    # y0 defaults to the mean before t_step (0.5), y_final to the tail mean (2.5)
    ts = M.settling_time(t, y, t_step=t_step)
    assert abs(ts - TS_FO) < DT
    # without t_step the time would be counted from t[0]
    assert abs(M.settling_time(t, y) - (TS_FO + t_step)) < DT


def test_never_settling_returns_nan():
    t = np.arange(0.0, 1.0, DT)
    assert math.isnan(M.settling_time(t, t))  # ramp: tail mean is never held
    t_short = np.arange(0.0, 2 * TAU, DT)     # still rising at the end of the record
    assert math.isnan(M.settling_time(t_short, first_order(t_short), y0=0.0, y_final=1.0))
    assert math.isnan(M.settling_time(t, np.ones_like(t)))  # zero step


def test_inside_band_from_the_start_is_zero():
    t = np.arange(0.0, 0.1, DT)
    assert M.settling_time(t, np.ones_like(t), y0=0.0, y_final=1.0) == 0.0


def test_settling_time_errors():
    t = np.arange(0.0, 0.1, DT)
    with pytest.raises(ValueError, match="t and y differ in shape"):
        M.settling_time(t, t[:-1])
    with pytest.raises(ValueError, match="t: sample times must be strictly increasing"):
        M.settling_time(t[::-1], t)
    with pytest.raises(ValueError, match="y: non-finite"):
        M.settling_time(t, np.full_like(t, np.nan))
    with pytest.raises(ValueError, match="band"):
        M.settling_time(t, t, band=0.0)


def test_smoothing_effect_on_clean_first_order_step():
    t = np.arange(0.0, 0.5, DT)
    y = first_order(t)
    # centered median: a clean monotone response is unchanged
    ts_med = M.settling_time(t, y, smooth_s=0.031, smooth_method="median")
    assert ts_med == pytest.approx(M.settling_time(t, y), abs=1e-12)
    # centered n-sample mean of exp(-t/tau): exp(-t/tau) * sinh(n a) / (n sinh a), a = dt/(2 tau)
    n, a = 31, DT / (2 * TAU)
    gain = math.sinh(n * a) / (n * math.sinh(a))
    ts_mean = M.settling_time(t, y, smooth_s=n * DT, y0=0.0, y_final=1.0)
    assert ts_mean == pytest.approx(TAU * math.log(50.0 * gain), abs=1e-4)
    with pytest.raises(ValueError, match="smooth_method"):
        M.settling_time(t, y, smooth_s=0.01, smooth_method="gauss")


@pytest.mark.parametrize("sigma, tol_median, tol_each", [(0.01, 0.05, 0.15), (0.03, 0.20, 0.50)])
def test_robust_settling_time_on_noisy_first_order_step(sigma, tol_median, tol_each):
    """Noise of 1-3 % of the step defeats the raw 2 % band test, not the robust one."""
    t = np.arange(0.0, 1.0, DT)
    robust, robust_auto = [], []
    for seed in range(10):
        y = first_order(t) + sigma * np.random.default_rng(seed).standard_normal(t.size)
        raw = M.settling_time(t, y)
        assert math.isnan(raw) or raw > 5 * TS_FO
        robust.append(M.settling_time_robust(t, y, t_step=0.0, noise_sigma=sigma))
        robust_auto.append(M.settling_time_robust(t, y))  # sigma estimated from the record
    for values in (np.array(robust), np.array(robust_auto)):
        assert np.all(np.isfinite(values))
        assert abs(np.median(values) - TS_FO) < tol_median * TS_FO
        assert np.all(np.abs(values - TS_FO) < tol_each * TS_FO)


def test_robust_ste_small_step_noise_6pct():
    """Rig-like small step (noise 6 % of the step, 0.2 s before it, 2.8 s after, quantized):
    the same window on both responses and y_final from the settled part keep STE small."""
    t = np.arange(0.0, 3.0005, DT)
    t_step = 0.2
    y = np.where(t < t_step, 0.0, 0.08 * second_order(t - t_step, 100.0, 0.55))
    stes = []
    for seed in range(20):
        y_meas = y + 0.005 * np.random.default_rng(seed).standard_normal(t.size)
        y_meas = np.round(y_meas / 0.002) * 0.002
        out = M.step_metrics(t, y_meas, y, t_step=t_step, noise_sigma=0.005)
        stes.append(out["ste_s"])
        assert out["ts_sim_s"] < 0.3
    assert max(stes) < 0.01


def test_settling_times_vectorized_matches_scalar():
    t = np.arange(0.0, 1.2, DT)
    t_step = 0.2
    rng = np.random.default_rng(4)
    rows = []
    for tau in (0.01, 0.02, 0.05):
        rows.append(np.where(t < t_step, 0.0, first_order(t - t_step, tau)))
    for wn, zeta in ((80.0, 0.3), (120.0, 0.6)):
        rows.append(np.where(t < t_step, 0.0, 2.0 * second_order(t - t_step, wn, zeta)))
    rows.append(t.copy())                                        # never settles
    rows.append(np.zeros_like(t))                                # zero step
    Y = np.array(rows)
    Y_noisy = Y + 0.02 * rng.standard_normal(Y.shape)
    for YY in (Y, Y_noisy):
        for smooth_s, method in ((None, "mean"), (0.021, "mean"), (0.015, "median")):
            vec = M.settling_times(t, YY, t_step=t_step, smooth_s=smooth_s, smooth_method=method)
            ref = [M.settling_time(t, y, t_step=t_step, smooth_s=smooth_s, smooth_method=method)
                   for y in YY]
            np.testing.assert_array_equal(vec, np.array(ref))
    w = M.smoothing_window_s(t, Y_noisy[1], t_step=t_step, noise_sigma=0.02)
    vec = M.settling_times(t, Y_noisy, t_step=t_step, smooth_s=w, settled_final=True)
    ref = [M.settling_time_robust(t, y, t_step=t_step, noise_sigma=0.02) if k == 1 else math.nan
           for k, y in enumerate(Y_noisy)]
    assert vec[1] == ref[1]
    assert math.isnan(vec[-2]) and math.isnan(vec[-1])
    # 1-D input is one response
    assert M.settling_times(t, Y[0], t_step=t_step)[0] == M.settling_time(t, Y[0], t_step=t_step)
    with pytest.raises(ValueError, match="t and Y differ in length"):
        M.settling_times(t[:-1], Y)


def test_estimate_noise_sigma():
    t = np.arange(0.0, 1.0, DT)
    y = first_order(t) + 0.02 * np.random.default_rng(1).standard_normal(t.size)
    assert M.estimate_noise_sigma(y) == pytest.approx(0.02, rel=0.1)


def test_smoothing_window_grows_with_noise():
    t = np.arange(0.0, 1.0, DT)
    y = first_order(t)
    assert M.smoothing_window_s(t, y, noise_sigma=0.0) == 0.0
    w1 = M.smoothing_window_s(t, y, noise_sigma=0.01)
    w3 = M.smoothing_window_s(t, y, noise_sigma=0.03)
    # moving mean: n >= (5 * sigma / 0.02)^2, odd: 6.25 -> 7 samples, 56.25 -> 57 samples
    assert w1 == pytest.approx(7 * DT)
    assert w3 == pytest.approx(57 * DT)
    # median: (1.2533 * 5 * sigma / 0.02)^2: 9.8 -> 11 samples
    assert M.smoothing_window_s(t, y, noise_sigma=0.01, smooth_method="median") == pytest.approx(11 * DT)
    # capped at 20 % of the post-step record
    assert M.smoothing_window_s(t, y, noise_sigma=1.0) == pytest.approx(201 * DT)


def test_resolvable_band_widens_only_when_the_window_is_capped():
    t = np.arange(0.0, 1.0, DT)
    y = first_order(t)
    # n = (5 sigma / 0.02)^2 = 57 samples fit below the cap (200 -> 201): the 2 % band stands
    assert M.resolvable_band(t, y, noise_sigma=0.03) == 0.02
    assert M.resolvable_band(t, y, noise_sigma=0.0) == 0.02
    # sigma = 1 (100 % of the step) needs 62500 samples: capped at 201, the band is 5 sigma / sqrt(201) / step
    step = float(np.mean(y[-100:]) - y[0])              # y_final: tail mean of the last 10 %; y0: first sample
    b = M.resolvable_band(t, y, noise_sigma=1.0)
    assert b == pytest.approx(5.0 / math.sqrt(201) / step, rel=1e-12)
    # with that band the window is the cap itself: the band test fits the noise it can average away
    assert M.smoothing_window_s(t, y, noise_sigma=1.0, band=b) == pytest.approx(201 * DT)
    # a noisy record (noise 40 % of the step, 0.2 s before it) settles in the band its noise resolves
    tn = np.arange(-200, 1000) * DT
    yn = np.where(tn >= 0, 1.0 - np.exp(-np.maximum(tn, 0.0) / TAU), 0.0)
    yn = yn + 0.4 * np.random.default_rng(3).standard_normal(tn.size)
    b4 = M.resolvable_band(tn, yn, t_step=0.0, noise_sigma=0.4)
    assert 0.1 < b4 < 0.2                                # 5 * 0.4 / sqrt(201) = 0.141 of a unit step
    # the settling time into a band b4 of a first-order step is tau ln(1/b4), delayed by the 201-sample moving
    # mean by tau ln(sinh(x)/x), x = window / (2 tau) (module docstring of harness.analysis.core.settling)
    ts = M.settling_time_robust(tn, yn, t_step=0.0, noise_sigma=0.4, band=b4)
    x = 201 * DT / (2 * TAU)
    assert ts == pytest.approx(TAU * math.log(1.0 / b4) + TAU * math.log(math.sinh(x) / x), abs=0.015)


def test_settling_time_error():
    t = np.arange(0.0, 0.5, DT)
    ste = M.settling_time_error(t, first_order(t, 0.02), t, first_order(t, 0.03))
    assert ste == pytest.approx(0.01 * math.log(50.0), abs=2e-4)
    # noisy measurement of the same response as the simulation: STE small
    y_meas = first_order(t) + 0.02 * np.random.default_rng(3).standard_normal(t.size)
    ste_noisy = M.settling_time_error(t, y_meas, t, first_order(t), noise_sigma=0.02)
    assert ste_noisy < 0.2 * TS_FO
    assert M.settling_time_error(t, y_meas, t, first_order(t), noise_sigma="auto") < 0.2 * TS_FO
    # a simulation that never settles gives nan
    assert math.isnan(M.settling_time_error(t, first_order(t), t, t))
    with pytest.raises(ValueError, match="y_sim: non-finite"):
        M.settling_time_error(t, first_order(t), t, np.full_like(t, np.nan))
    with pytest.raises(ValueError, match="t_meas and y_meas differ in shape"):
        M.settling_time_error(t[:-1], first_order(t), t, first_order(t), noise_sigma=0.01)


# --------------------------------------------------------------------------- sinusoids
F = 1.0  # Hz


def test_sine_amplitude_phase_exact():
    t = np.arange(0.0, 3.0, DT)
    A, phi = M.sine_amplitude_phase(t, 1.5 * np.sin(2 * np.pi * F * t + 0.7), F)
    assert A == pytest.approx(1.5, abs=1e-9)
    assert phi == pytest.approx(0.7, abs=1e-9)
    A, phi = M.sine_amplitude_phase(t, 0.2 * np.sin(2 * np.pi * F * t - 2.9), F)
    assert (A, phi) == (pytest.approx(0.2, abs=1e-9), pytest.approx(-2.9, abs=1e-9))
    # amplitude is reported positive: -sin(x) = sin(x + pi), phase pi not -pi
    A, phi = M.sine_amplitude_phase(t, -np.sin(2 * np.pi * F * t), F)
    assert A == pytest.approx(1.0) and phi == pytest.approx(math.pi)


def test_sine_amplitude_phase_noise_offset_drift():
    t = np.arange(0.0, 5.0, DT)
    rng = np.random.default_rng(0)
    y = 3.0 + 0.4 * np.sin(2 * np.pi * F * t - 1.1) + 0.02 * rng.standard_normal(t.size)
    A, phi = M.sine_amplitude_phase(t, y, F)
    assert A == pytest.approx(0.4, abs=3e-3) and phi == pytest.approx(-1.1, abs=1e-2)
    y_drift = y + 0.3 * t  # slow drift
    A, phi = M.sine_amplitude_phase(t, y_drift, F, drift=True)
    assert A == pytest.approx(0.4, abs=3e-3) and phi == pytest.approx(-1.1, abs=1e-2)


def test_harmonics_with_drift():
    """A 2f component leaks through a drift term unless the harmonics are fitted too."""
    t = np.arange(0.0, 2.0, DT)
    w = 2 * np.pi * F
    y = 1.0 + 0.5 * np.sin(w * t - 1.0) + 0.3 * np.sin(2 * w * t + 0.4) + 0.05 * t
    A, phi = M.sine_amplitude_phase(t, y, F, drift=True, harmonics=2)
    assert A == pytest.approx(0.5, abs=1e-9) and phi == pytest.approx(-1.0, abs=1e-9)
    A_bad, _ = M.sine_amplitude_phase(t, y, F, drift=True)
    assert abs(A_bad - 0.5) > 0.01
    # without drift, over whole periods, the harmonic does not matter
    y_nodrift = y - 0.05 * t
    A, phi = M.sine_amplitude_phase(t, y_nodrift, F)
    assert A == pytest.approx(0.5, abs=1e-9) and phi == pytest.approx(-1.0, abs=1e-9)
    with pytest.raises(ValueError, match="harmonics"):
        M.sine_amplitude_phase(t, y, F, harmonics=0)


def test_amplitude_ratio_phase_shift_sign_convention():
    t = np.arange(0.0, 6.0, DT)
    w = 2 * np.pi * F
    y_meas = 2.0 + 1.0 * np.sin(w * t + 0.5)
    lagging = 2.0 + 0.9 * np.sin(w * (t - 0.2 / w) + 0.5)  # delayed copy: lags by 0.2 rad
    ratio, shift = M.amplitude_ratio_phase_shift(t, y_meas, lagging, F)
    assert ratio == pytest.approx(0.9, abs=1e-9)
    assert shift == pytest.approx(-0.2, abs=1e-9)
    leading = 1.0 * np.sin(w * (t + 0.3 / w) + 0.5)        # advanced copy: leads
    assert M.amplitude_ratio_phase_shift(t, y_meas, leading, F)[1] == pytest.approx(0.3, abs=1e-9)


def test_phase_shift_wraps():
    t = np.arange(0.0, 4.0, DT)
    w = 2 * np.pi * F
    _, shift = M.amplitude_ratio_phase_shift(t, np.sin(w * t + 3.0), np.sin(w * t - 3.0), F)
    assert shift == pytest.approx(2 * math.pi - 6.0, abs=1e-9)  # -6 rad wrapped into (-pi, pi]
    assert -math.pi < shift <= math.pi


def test_amplitude_ratio_skips_transient_with_last_periods():
    t = np.arange(0.0, 5.0, DT)
    w = 2 * np.pi * F
    rng = np.random.default_rng(2)
    y_meas = 0.5 + 1.0 * np.sin(w * t) + 0.02 * rng.standard_normal(t.size)
    y_sim = 0.5 + 0.95 * np.sin(w * t - 0.25) + 3.0 * np.exp(-t / 0.3)  # start-up transient
    ratio, shift = M.amplitude_ratio_phase_shift(t, y_meas, y_sim, F, periods=2)
    assert ratio == pytest.approx(0.95, abs=5e-3)
    assert shift == pytest.approx(-0.25, abs=5e-3)
    ratio_all, _ = M.amplitude_ratio_phase_shift(t, y_meas, y_sim, F, periods=5)
    assert abs(ratio_all - 0.95) > 0.01  # the transient spoils a whole-record fit
    with pytest.raises(ValueError, match="periods"):
        M.amplitude_ratio_phase_shift(t, y_meas, y_sim, F, periods=6)


def test_sine_metrics_keys():
    t = np.arange(0.0, 4.0, DT)
    w = 2 * np.pi * F
    out = M.sine_metrics(t, np.sin(w * t), 0.9 * np.sin(w * t - 0.1), F, periods=3)
    assert set(out) == {"amplitude_ratio", "phase_shift_rad", "rmse_mm"}
    assert out["amplitude_ratio"] == pytest.approx(0.9)
    assert out["phase_shift_rad"] == pytest.approx(-0.1)
    assert "rmse_N" in M.sine_metrics(t, np.sin(w * t), np.sin(w * t), F, unit="N")


@pytest.mark.parametrize("change,match", [
    (dict(t=np.arange(2) * DT), r"^t: need at least 3 samples, got 2$"),
    (dict(t=np.arange(4000)[::-1] * DT), r"^t: sample times must be strictly increasing$"),
    (dict(y_meas=np.zeros(3999)), r"^t and y_meas differ in shape: \(4000,\) vs \(3999,\)$"),
    (dict(y_sim=np.zeros(3999)), r"^t and y_sim differ in shape: \(4000,\) vs \(3999,\)$"),
    (dict(y_meas=np.r_[np.nan, np.ones(3999)]), r"^y_meas: non-finite value .*nan.* at index 0$"),
    (dict(y_sim=np.zeros((4000, 2))), r"^y_sim: expected a 1-D array, got shape \(4000, 2\)$"),
    (dict(frequency_hz=0.0), r"^frequency_hz: must be positive and finite, got 0\.0$"),
])
def test_sine_functions_check_inputs_alike(change, match):
    """amplitude_ratio_phase_shift and sine_metrics share their input checks and messages."""
    t = np.arange(4000) * DT
    args = dict(t=t, y_meas=np.sin(2 * np.pi * F * t), y_sim=np.sin(2 * np.pi * F * t), frequency_hz=F)
    args.update(change)
    for fn in (M.amplitude_ratio_phase_shift, M.sine_metrics):
        with pytest.raises(ValueError, match=match):
            fn(**args)


# --------------------------------------------------------------------------- sweeps
def test_sweep_rmse_matches_common_gaps():
    gap_meas = np.arange(0.0, 26.0, 1.0)       # 25 .. 0 mm in 1 mm steps (order irrelevant)
    y_meas = np.linspace(1.0, 0.0, gap_meas.size)
    gap_sim = np.arange(0.0, 10.5, 0.5)[::-1] + 1e-12   # float noise far below 1e-9 mm
    y_sim = np.interp(gap_sim, gap_meas, y_meas) + 0.1
    assert M.sweep_rmse(gap_meas, y_meas, gap_sim, y_sim) == pytest.approx(0.1)
    with pytest.raises(ValueError, match="no gap in common"):
        M.sweep_rmse([1.0, 2.0], [0.1, 0.2], [1.5, 2.5], [0.1, 0.2])
    with pytest.raises(ValueError, match="gap_sim"):
        M.sweep_rmse([1.0], [0.1], [1.0, 1.0], [0.1, 0.2])
    with pytest.raises(ValueError, match="gap_meas and y_meas differ in shape"):
        M.sweep_rmse([1.0, 2.0], [0.1], [1.0], [0.1])


# --------------------------------------------------------------------------- convenience
def test_step_metrics():
    t = np.arange(0.0, 0.5, DT)
    out = M.step_metrics(t, first_order(t, 0.02), first_order(t, 0.03))
    assert set(out) == {"rmse_mm", "ts_meas_s", "ts_sim_s", "ste_s", "smooth_window_s"}
    assert out["smooth_window_s"] == 0.0
    assert out["ts_meas_s"] == pytest.approx(0.02 * math.log(50), abs=1e-4)
    assert out["ts_sim_s"] == pytest.approx(0.03 * math.log(50), abs=1e-4)
    assert out["ste_s"] == pytest.approx(out["ts_sim_s"] - out["ts_meas_s"])
    assert out["rmse_mm"] == pytest.approx(M.rmse(first_order(t, 0.02), first_order(t, 0.03)))
    # simulation on a finer grid is interpolated onto the measured one
    t_fine = np.arange(0.0, 0.5 + 1e-4, 1e-4)
    out2 = M.step_metrics(t, first_order(t), first_order(t_fine), t_sim=t_fine, unit="N")
    assert out2["rmse_N"] < 1e-4 and out2["ste_s"] < 1e-4
    # noisy measurement of the simulated response: robust STE with one window for both
    y_meas = first_order(t) + 0.03 * np.random.default_rng(5).standard_normal(t.size)
    out3 = M.step_metrics(t, y_meas, first_order(t), noise_sigma=0.03)
    # 57 samples for the nominal unit step; y0 = y[0] is itself noisy here (no pre-step samples)
    assert 50 * DT < out3["smooth_window_s"] < 64 * DT
    assert out3["ste_s"] < 0.25 * TS_FO  # 16 ms for this seed; median over seeds ~5 ms
    assert out3["rmse_mm"] == pytest.approx(0.03, rel=0.1)


# --------------------------------------------------------------------------- grouped options
def test_smoothing_samples_by_hand():
    from harness.analysis.core.settling import smoothing_samples
    t = np.arange(100) * DT
    assert smoothing_samples(t, None) == 1 and smoothing_samples(t, 0.0) == 1
    assert smoothing_samples(t, 0.0104) == 11          # round(10.4) = 10 samples -> odd 11
    assert smoothing_samples(t, 0.0094) == 9
    assert smoothing_samples(t, 1.0) == 99             # at most the record (odd)


def test_step_levels_and_window_rule():
    t = np.arange(0, 0.5, DT)
    y = 2.0 - 3.0 * first_order(t)                    # from 2 to -1
    lv = M.StepLevels(y0=2.0, y_final=-1.0)
    assert M.settling_times(t, y, levels=lv)[0] == pytest.approx(M.settling_time(t, y, y0=2.0, y_final=-1.0))
    assert abs(M.settling_times(t, y, levels=lv)[0] - TS_FO) < 1e-4
    # window: smallest odd n with margin * sigma / sqrt(n) <= band * |step|: (5 * 0.01 / 0.06)^2 = 0.69 -> 1,
    # (10 * 0.01 / 0.06)^2 = 2.8 -> 3 samples
    assert M.smoothing_window_s(t, y, noise_sigma=0.01, levels=lv) == 0.0
    assert M.smoothing_window_s(t, y, noise_sigma=0.01, levels=lv, rule=M.WindowRule(margin=10.0)) == \
        pytest.approx(3 * DT)
    assert M.smoothing_window_s(t, y, noise_sigma=1.0, levels=lv, rule=M.WindowRule(max_fraction=0.01)) == \
        pytest.approx(5 * DT)                          # capped at 1 % of 500 samples, made odd
