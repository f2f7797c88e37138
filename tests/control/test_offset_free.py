"""Offset-free MPC on an estimator (harness.control.estimator + closedloop.EstimatedMpcLoop), issue 26's done-when:

* the paper model on a saturating plant (filler_saturation at the virtual rig's magnitude 1, ksat = 3 1/T^2) on
  the study's staircase toward pull-in (clipped to the plant's holdable range at 30 V): the offset-free MPC, fed
  noisy x and I only (the rig's noise floors), ends every hold within 20 um of the setpoint (read one MPC
  horizon before the next setpoint: the MPC leaves the hold that early to preview the next step); the MPC without
  disturbance model, fed the exact states, stops short by more than 0.5 mm on the upper holds (its offset);
* on a clean plant, the MPC on the estimator (noisy x and I only) tracks the 2 Hz 0 -> 1 mm stroke with a RMSE
  at most 1.5x the full-state MPC's (exact I, x, v); neither touches the coil;
* the MPC's prediction with the estimator's parameter overrides is the prediction of the model with those
  parameters (an MPC built on them).
"""
from __future__ import annotations

import numpy as np
import pytest

from fmu_src.specs import BLOCK, Params
from fmu_src.statics import Statics
from harness.control.closedloop import (EstimatedMpcLoop, LoopSettings, MpcLoop, hold_end_errors, metrics, run_loop,
                                        staircase_to_pull_in, stroke_profile)
from harness.control.estimator import Ekf, EkfSettings, NoiseLevels
from harness.control.mpc import Mpc, MpcSettings, rollouts
from harness.control.opmap import holdable_limit
from harness.control.study import clip_profile

MS = MpcSettings()
LOOP = LoopSettings(dt_s=1e-3, every=10, horizon_points=MS.horizon + 1)


def _estimated(p, offset_free, seed=0):
    noise = NoiseLevels.from_rig()
    return EstimatedMpcLoop(Mpc(p, MS), Ekf(p, noise, EkfSettings(dt_s=MS.dt_s, offset_free=offset_free)), noise, seed)


def test_offset_free_mpc_ends_every_hold_on_a_saturating_plant(fmu_path):
    paper = Params()
    plant = paper.with_(ksat=3.0)
    prof = clip_profile(staircase_to_pull_in(holdable_limit(paper)[0]), Statics(plant, MS.V_max_V).x_holdable)
    preview = MS.horizon * MS.dt_s
    ctl = _estimated(paper, offset_free=True)
    run = run_loop(fmu_path, plant, ctl, prof, LOOP)
    err = hold_end_errors(run, prof, preview)
    assert len(err) == len(prof.levels_m) + 1
    assert np.all(np.abs(err) <= 20e-6), err
    assert metrics(run)["contact_events"] == 0
    plain = run_loop(fmu_path, plant, MpcLoop(Mpc(paper, MS)), prof, LOOP)
    short = hold_end_errors(plain, prof, preview)
    assert np.all(short[-3:] < -0.5e-3), short   # the offset the disturbance model removes


def test_estimator_mpc_stroke_within_1_5x_full_state(fmu_path):
    p = Params()
    full = run_loop(fmu_path, p, MpcLoop(Mpc(p, MS)), stroke_profile(1e-3, 2.0), LOOP)
    for offset_free in (False, True):
        est = run_loop(fmu_path, p, _estimated(p, offset_free), stroke_profile(1e-3, 2.0), LOOP)
        m, m0 = metrics(est), metrics(full)
        assert m["rmse_m"] <= 1.5 * m0["rmse_m"], (offset_free, m["rmse_m"], m0["rmse_m"])
        assert m["contact_events"] == 0 == m0["contact_events"]


def test_prediction_overrides_are_the_overridden_model():
    p = Params()
    q = p.with_(Em=0.8 * p.Em, ksat=2.0)
    ref = np.full(MS.horizon, 1.5e-3)
    y = (0.3, 0.4e-3, 0.0)
    a, b = Mpc(p, MS), Mpc(q, MS)
    over = ((BLOCK.param["Em"], q.Em), (BLOCK.param["ksat"], 2.0), (BLOCK.switch["filler_saturation"], 1.0))
    a.command(0.0, ref, y, (0.5, over))
    b.model.integ.reset(0.0, list(y))   # the overridden model's own prediction of a's voltages (+ the 0.5 V offset)
    X = np.empty((1, MS.horizon))
    Z = (np.repeat(a.z, MS.blocks) + 0.5)[None, :]
    rollouts(b.model.integ.S, b.model.integ.W, b.model.integ.coef, 0.0, MS.dt_s, np.ascontiguousarray(Z), X)
    assert a.last_predicted == pytest.approx(X[0], rel=1e-9, abs=1e-12)
