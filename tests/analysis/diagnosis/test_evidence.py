"""Residual features of the diagnosis (harness.analysis.diagnosis.evidence) on hand-made records."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness.analysis.diagnosis.evidence import combine_z, current_drift, features, pointing_to, time_shift
from harness.analysis.diagnosis.jobs import Trace
from harness.analysis.diagnosis.prepare import SampleData, Series

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
