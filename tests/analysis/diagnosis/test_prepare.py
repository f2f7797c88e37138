"""Dataset -> prepared samples (harness.analysis.diagnosis.prepare) on small hand-made datasets."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness.analysis.diagnosis import DiagnoseSettings
from harness.analysis.diagnosis.prepare import PrepareError, Series, Sweep, noise_floors, prepare
from harness.data.dataset import Dataset, GapSweep, Sample, TimeSeries
from harness.data.protocol import NoiseFloorError


def make_ds(rig: dict, sigma_mm: float = 0.0, seed: int = 1) -> Dataset:
    rng = np.random.default_rng(seed)
    t = np.arange(3001) * 1e-3
    V = np.where(t >= 0.2 - 1e-12, 4.0, 0.0)
    I = np.where(V > 0, 0.8, 0.0) + rng.normal(0, 1e-4, t.size)
    x = np.where(V > 0, 0.1, 0.0) + rng.normal(0, sigma_mm, t.size)
    F = np.where(V > 0, 0.2, 0.0) + rng.normal(0, 1e-3, t.size)
    tests = {
        "T5": TimeSeries("T5", None, t, V, I, x, None, 0.23, 5.0),
        "T8": TimeSeries("T8", None, t, V, I, None, F, 0.23, 2.0),
        "T1": GapSweep("T1", None, np.arange(5.0, -1.0, -1.0), np.full(6, 0.8), np.linspace(0.01, 0.5, 6), None,
                       0.23),
    }
    return Dataset(None, True, "test", rig, [Sample("W20-D45", 20.0, 45.0, 1.0, tests)])


RIG = {"coil_radius_mm": 20.0, "field_per_amp_T_per_A": 0.29, "sample_period_s": 1e-3,
       "sweep_hold_s": 1.5, "sweep_average_s": 0.3,
       "sensors": {"displacement_mm": {"noise_floor": 0.005}, "force_N": {"noise_floor": 5e-4},
                   "current_A": {"noise_floor": 2e-4}}}


def test_prepared_tests():
    prep = prepare(make_ds(RIG), DiagnoseSettings())
    sd = prep.samples[0]
    assert (sd.a, sd.D, sd.kB) == (0.02, 0.045, 0.29)
    t5, t8, t1 = sd.tests["T5"], sd.tests["T8"], sd.tests["T1"]
    assert isinstance(t5, Series) and isinstance(t1, Sweep)
    assert t5.k_on == 200 and t5.V_on == 4.0 and not t5.blocked and t8.blocked
    assert t5.r0 == pytest.approx(5e-3) and t5.sig_y == pytest.approx(5e-6) and t8.sig_y == 5e-4
    assert t1.V_on == 4.0                                   # the step voltage at the same field
    # a sweep reading averages 300 samples, at least 0.5 x the floor
    assert t1.sig_y == pytest.approx(max(5e-6 / math.sqrt(300), 0.5 * 5e-6))
    assert np.all(t1.gaps == np.arange(5.0, -1.0, -1.0) / 1e3)
    assert prep.floors.as_dict() == {"displacement_mm": 0.005, "force_N": 5e-4, "current_A": 2e-4}


def test_noise_floor_estimated_without_the_manifest():
    rig = {k: v for k, v in RIG.items() if k != "sensors"}
    fl = noise_floors(make_ds(rig, sigma_mm=0.004))
    assert fl.displacement_mm == pytest.approx(0.004, rel=0.15)
    assert fl.current_A == pytest.approx(1e-4, rel=0.15)


def test_missing_rig_data_raises():
    with pytest.raises(PrepareError, match="coil_radius_mm"):
        prepare(make_ds({k: v for k, v in RIG.items() if k != "coil_radius_mm"}), DiagnoseSettings())
    with pytest.raises(NoiseFloorError, match="noise"):
        noise_floors(make_ds({k: v for k, v in RIG.items() if k != "sensors"}, sigma_mm=0.0))
