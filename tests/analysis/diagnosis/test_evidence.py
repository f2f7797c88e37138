"""Residual features of the diagnosis (harness.analysis.diagnosis.evidence) on hand-made records."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness.analysis.diagnosis.evidence import combine_z, current_drift, features, pointing_to, time_shift
from harness.analysis.diagnosis.jobs import Trace
from harness.analysis.diagnosis.prepare import SampleData, Series
from harness.analysis.diagnosis.result import records

T = np.arange(3001) * 1e-3            # 0.2 s before the step, 2.8 s after
K_ON = 200
TL = T - T[K_ON]


def series(name, I, y, sig_y=1e-6, sig_I=1e-4):
    V = np.where(T >= T[K_ON], 5.0, 0.0)
    return Series(name=name, blocked=False, r0=5e-3, field_T=0.23, t=T, V=V, I=I, y=y, k_on=K_ON, V_on=5.0,
                  sig_y=sig_y, sig_I=sig_I)


def sample(tests):
    return SampleData(sid="W20-D45", wt_pct=20.0, diameter_mm=45.0, a=0.02, D=0.045, kB=0.29, tests=tests)


def test_combine_z():
    assert combine_z([1.0, 2.0, float("nan")]) == pytest.approx(3.0 / math.sqrt(2.0))
    assert math.isnan(combine_z([]))


def test_current_drift_of_a_linear_droop():
    """I falls by 1 %/s after the step: early (0.3-1.3 s) and late (last second) means by hand."""
    I = np.where(TL >= 0, 1.0 - 0.01 * TL, 0.0)
    sd = sample({"T5": series("T5", I, np.zeros(T.size))})
    f = current_drift([sd], {})
    row = f["per_sample"]["W20-D45"]["T5"]
    Ie, Il = 1.0 - 0.01 * np.mean(np.arange(300, 1300) / 1000), 1.0 - 0.01 * 2.3
    assert row["early_A"] == pytest.approx(Ie, rel=1e-9) and row["late_A"] == pytest.approx(Il, rel=1e-9)
    assert row["change_pct"] == pytest.approx(100 * (Il - Ie) / Ie, rel=1e-9)
    assert row["z"] == pytest.approx((Il - Ie) / (1e-4 * math.sqrt(1 / 1000 + 1 / 1001)), rel=1e-9)
    assert f["z"] == pytest.approx(row["z"]) and "coil_heating" in f["points_to"]


def test_time_shift_finds_a_delay():
    """A reading delayed by 2 ms against the model's first-order rise: delay about 2 ms."""
    def rise(s):
        return np.where(s > 0, 1e-3 * (1.0 - np.exp(-np.maximum(s, 0) / 0.02)), 0.0)
    t5 = series("T5", np.where(TL >= 0, 0.8, 0.0), rise(TL - 0.002))
    tr = Trace(kind="series", x=T, y_meas=t5.y, y_sim=rise(TL), I_meas=t5.I, I_sim=t5.I, blocked=False)
    f = time_shift([sample({"T5": t5})], {0: {"T5": tr}})
    assert f["per_sample"]["W20-D45"]["T5"]["delay_ms"] == pytest.approx(2.0, rel=0.05)
    assert math.isnan(f["z"])                      # z is T8's alone


def test_features_point_to_catalogue_effects():
    sd = sample({})
    feats = features([sd], {})
    assert list(feats) == ["current_drift", "displacement_drift", "field_dependence", "deflection_dependence",
                           "motion_current", "time_shift"]
    assert pointing_to(feats, "coil_heating") == ["current_drift", "displacement_drift"]
    assert pointing_to(feats, "sensor_lag") == ["time_shift"]


# ---------------------------------------------------------------- the step instant within a sample (coarse grid)
DT_C = 1.0 / 245.0                    # 245 Hz: 0.3 s and 1.3 s are 73.5 and 318.5 periods
PHASE = 0.37                          # the step comes 0.37 periods after sample K_C - 1 ...
K_C = 50
T_C = 12.0 + np.arange(736) * DT_C    # ... on a clock starting at 12 s; 3 s record
T_STEP = T_C[K_C - 1] + PHASE * DT_C  # the true instant: 2.57 ms before the first sample reading the step
DELAY = T_C[K_C] - T_STEP
S = T_C - T_STEP                      # time since the true step [s]


def coarse(name, I, y, blocked=False, sig_y=1e-6, sig_I=1e-4, delay=DELAY):
    V = np.where(S >= 0, 5.0, 0.0)
    return Series(name=name, blocked=blocked, r0=5e-3, field_T=0.23, t=T_C, V=V, I=I, y=y, k_on=K_C, V_on=5.0,
                  sig_y=sig_y, sig_I=sig_I, step_delay_s=delay)


def rl_current(tau_e=0.008, I_ss=0.8):
    return np.where(S >= 0, I_ss * (1.0 - np.exp(-np.maximum(S, 0.0) / tau_e)), 0.0)


def test_the_step_instant_is_the_estimated_one_between_samples():
    t = coarse("T5", rl_current(), np.zeros(T_C.size))
    assert DELAY == pytest.approx(0.63 * DT_C)
    assert t.t_step_s == pytest.approx(T_STEP, abs=1e-12)
    assert coarse("T5", rl_current(), np.zeros(T_C.size), delay=0.0).t_step_s == T_C[K_C]


def test_a_blocked_force_following_i_squared_shows_no_delay_when_the_step_falls_mid_sample():
    """T8: F = c I^2 at once (no sensor lag); I the exact RL rise from the true instant, 2.52 ms before the
    first sample reading the step. A reference current started at that sample lags by 2.57 ms and makes
    the force look 2.6 ms early (delay -2.6 ms, z -25); from the estimated instant the delay is 0 within a
    small fraction of the sample period."""
    I = rl_current()
    F = 0.05 * (I / 0.8) ** 2
    t8 = coarse("T8", I, F, blocked=True, sig_y=5e-4)
    tr = Trace(kind="series", x=T_C, y_meas=F, y_sim=F, I_meas=I, I_sim=I, blocked=True)
    row = time_shift([sample({"T8": t8})], {0: {"T8": tr}})["per_sample"]["W20-D45"]["T8"]
    assert abs(row["delay_ms"]) < 0.05 * DT_C * 1e3, row
    assert abs(row["z"]) < 3.0, row


def test_drift_windows_count_from_the_estimated_instant():
    """current_drift's early window is 0.3-1.3 s after the step: the samples with 0.3 <= t - t_step < 1.3 for
    the true instant (not for the first sample reading the step); I = 1 - 0.01 (t - t_step) after it."""
    I = np.where(S >= 0, 1.0 - 0.01 * S, 0.0)
    t5 = coarse("T5", I, np.zeros(T_C.size))
    row = current_drift([sample({"T5": t5})], {})["per_sample"]["W20-D45"]["T5"]
    # by hand: t - t_step = (k - K_C) DT_C + DELAY; 0.3 <= . < 1.3 -> k from K_C + ceil((0.3 - DELAY)/DT_C)
    k0 = K_C + math.ceil((0.3 - DELAY) / DT_C)
    k1 = K_C + math.ceil((1.3 - DELAY) / DT_C)           # first sample past the window
    ks = np.arange(k0, k1)
    # 73.5 - 0.63 and 318.5 - 0.63 periods: the window starts and ends one sample earlier than it would from
    # the first sample reading the step (74 .. 318)
    assert (k0, k1) == (K_C + 73, K_C + 318)
    assert row["early_A"] == pytest.approx(float(np.mean(1.0 - 0.01 * ((ks - K_C) * DT_C + DELAY))), rel=1e-12)


def test_settling_times_are_counted_from_the_estimated_instant():
    """Step metrics of a first-order displacement rise y = A (1 - exp(-s/tau_m)), tau_m = 50 ms, s = t - t_step.

    By hand, with the documented final level (``settling``: provisional final = mean of the second half of
    the post-step samples, settling time Ts1 with it, final yf = mean of the samples from t_step + Ts1 on):
    the 2 % band is entered at s = -tau_m ln(1 - 0.98 yf / A) (about tau_m ln 50 = 195.6 ms; the tail mean
    lies slightly below A). Band entry is interpolated between samples (error ~ dt^2/(8 tau_m) < 0.05 ms).
    Counted from the first sample reading the step it would be 2.6 ms shorter."""
    tau_m, A = 0.05, 1e-3
    y = np.where(S >= 0, A * (1.0 - np.exp(-np.maximum(S, 0.0) / tau_m)), 0.0)
    t3 = coarse("T3", rl_current(), y, sig_y=0.0)
    tr = Trace(kind="series", x=T_C, y_meas=y, y_sim=y, I_meas=t3.I, I_sim=t3.I, blocked=False)
    (rec,) = records([sample({"T3": t3})], {0: {"T3": tr}})
    post = np.flatnonzero(S >= 0)
    yf1 = float(np.mean(y[post[post.size // 2:]]))
    ts1 = -tau_m * math.log(1.0 - 0.98 * yf1 / A)
    yf = float(np.mean(y[S >= ts1]))
    ts = -tau_m * math.log(1.0 - 0.98 * yf / A)
    assert ts == pytest.approx(tau_m * math.log(50.0), abs=1.5e-3)
    assert rec["ts_meas_s"] == pytest.approx(ts, abs=2e-4), rec
    assert rec["ts_sim_s"] == pytest.approx(ts, abs=2e-4), rec
