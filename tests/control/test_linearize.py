"""harness.control.linearize against finite differences of the FMU: the FMU (driven by fmpy) is held at the
operating voltage until it rests, then the voltage steps by dV; the difference to the unstepped run, per
volt, is compared with the linear model's step response. Bound: 0.5 % of the response's peak for a 0.2 %
voltage step at the operating point; the error grows with the step (nonlinearity) and with the distance
between the operating point of the linearization and that of the FMU."""
from __future__ import annotations

import control
import numpy as np
import pytest

from fmu_src.specs import Params
from harness.control.linearize import linearize
from harness.sim.fmurun import run

T_SETTLE, T_STEP, DT = 1.5, 0.25, 1e-3


def fmu_step_per_volt(fmu_path, p, V0, dV):
    t = np.arange(0.0, T_SETTLE + T_STEP + DT / 2, DT)
    base = run(p, t, np.full(t.shape, V0), fmu_path=fmu_path, outputs=("x",))["x"]
    V = np.where(t >= T_SETTLE - DT / 2, V0 + dV, V0)
    stepped = run(p, t, V, fmu_path=fmu_path, outputs=("x",))["x"]
    k = t >= T_SETTLE - DT / 2
    return t[k] - T_SETTLE, (stepped[k] - base[k]) / dV


def rel_error(lin, tt, dx_per_V):
    lin_resp = np.squeeze(control.step_response(lin.sys, tt).outputs)
    return float(np.max(np.abs(dx_per_V - lin_resp)) / np.max(np.abs(lin_resp)))


def test_linearization_matches_fmu_small_steps_and_degrades_away(fmu_path):
    p = Params()
    lin = linearize(p, 1e-3)
    assert lin.sys.nstates == 3 and lin.V0_V == pytest.approx(13.4464, rel=1e-4)
    tt, small = fmu_step_per_volt(fmu_path, p, lin.V0_V, 0.002 * lin.V0_V)
    e_small = rel_error(lin, tt, small)
    assert e_small < 5e-3
    tt, large = fmu_step_per_volt(fmu_path, p, lin.V0_V, 0.1 * lin.V0_V)
    e_large = rel_error(lin, tt, large)
    assert e_large > 5 * e_small and e_large > 0.03          # a 10 % step: the nonlinearity shows
    lin_far = linearize(p, 2e-3)                               # the FMU at 1 mm, the model linearized at 2 mm
    assert rel_error(lin_far, tt, small) > 0.2


def test_linearization_of_an_effect_model_has_its_states():
    lin = linearize(Params().with_(Rth=8.0, tau_th=4.0, ksat=3.0), 1e-3)
    assert lin.state_names == ("I", "x", "v", "dT") and lin.sys.nstates == 4
    assert lin.dc_gain_m_per_V() > 0
