"""The holdable range of any model the diagnosis can produce (issue 21): the static map of a saturating, heating
or creeping model ends its range where no admissible voltage holds the diaphragm any more instead of raising, and
the controller FMU and the MPC initialise for every such model.

Independent checks: the saturated force's limit Em*G(r0 - x)/(ksat*kB^2) = K(x) and the voltage that holds x,
V = R*sqrt(K/(Em*G - ksat*kB^2*K)) (tests/fmu/test_statics.py's formula), both with the kernel of
tests/independent/physics.py and scipy's brentq. The property tests draw a rig sample, a gap and one or two
catalogue effects at magnitudes from 0.1 to 30 times the rig's realistic magnitude 1 (fast profile: a few
derandomized examples; deep profile: ``-m deep``)."""
from __future__ import annotations

import math
import shutil
import sys
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.fmi2 import FMU2Slave
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from fmu_src.specs import EFFECTS, Params
from fmu_src.statics import Statics
from harness.control.mpc import Mpc, MpcSettings
from harness.data import rig

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "independent"))
from physics import kernel_G  # noqa: E402  (independent: imports nothing of the project)

V_MAX = 30.0
_COMMON = dict(deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
FAST = settings(max_examples=4, derandomize=True, **_COMMON)
DEEP = settings(max_examples=150, **_COMMON)


def spring(p, x):
    return (p.K1 * x * x + p.K2) * x


def G(p, x):
    return kernel_G(p.r0 - x, p.a, p.D, p.kB)


def v_hold_indep(p, x, ksat):
    K = spring(p, x)
    return p.R * math.sqrt(K / (p.Em * G(p, x) - ksat * p.kB ** 2 * K))


# ------------------------------------------------------------------ hand-checked cases
def test_saturation_ends_the_range_where_the_saturated_force_meets_the_spring():
    """Params(ksat=10) raised "no current holds x" before; its range ends at the root of Em*G/(ksat*kB^2) = K
    (the force of an unlimited current), and at V_max where V(x) = V_max."""
    p = Params(ksat=10.0)
    x_sat = brentq(lambda x: p.Em * G(p, x) / (10.0 * p.kB ** 2) - spring(p, x), 1e-5, 5e-3, xtol=1e-13)
    s = Statics(p)
    assert s.limit == "saturation"
    assert s.x_holdable == pytest.approx(x_sat, rel=1e-6)
    xs, V = s.table(50)
    assert xs[-1] <= s.x_holdable and np.all(np.diff(V) > 0)
    with pytest.raises(ValueError, match="no current up to 10000 A holds x"):
        s.current_for(1.01 * x_sat)
    sv = Statics(p, V_max=V_MAX)
    x_v = brentq(lambda x: v_hold_indep(p, x, 10.0) - V_MAX, 1e-5, 0.999 * x_sat, xtol=1e-13)
    assert sv.limit == "voltage limit"
    assert sv.x_holdable == pytest.approx(x_v, rel=1e-6)
    assert sv.v_pull_in == pytest.approx(V_MAX, rel=1e-6)
    assert sv.clip(4e-3) == sv.x_holdable and sv.clip(0.5e-3) == 0.5e-3


def test_a_voltage_limit_above_the_pull_in_voltage_keeps_the_fold():
    p = Params()
    assert Statics(p, V_max=V_MAX).x_holdable == Statics(p).x_pull_in      # 20.48 V < 30 V: the fold
    x10 = brentq(lambda x: v_hold_indep(p, x, 0.0) - 10.0, 1e-6, 5e-3, xtol=1e-13)
    assert Statics(p, V_max=10.0).x_holdable == pytest.approx(x10, rel=1e-6)
    assert Statics(p, V_max=0.0).table() == (pytest.approx([0.0]), pytest.approx([0.0]))


# ------------------------------------------------------------------ property tests
@st.composite
def diagnosed_models(draw):
    """A rig sample at a gap of 3-9 mm with one or two catalogue effects at 0.1-30 x the realistic magnitude."""
    w, d = draw(st.sampled_from(rig.ALL_SAMPLES))
    base = rig.true_params(w, d).with_(r0=draw(st.sampled_from([0.003, 0.005, 0.009])))
    names = draw(st.lists(st.sampled_from(sorted(EFFECTS)), min_size=1, max_size=2, unique=True))
    kw = {}
    for n in names:
        kw.update(rig.effect_params(n, draw(st.floats(0.1, 30.0)), base))
    return base.with_(**kw).validated()


ISSUE = Params(ksat=10.0)
DIAGNOSED = rig.true_params(30, 30).with_(ksat=5.53, lam=0.54)   # the diagnosis of issue 21 on a stiff sample


def check_range(p):
    s = Statics(p, V_max=V_MAX)
    xh = s.x_holdable
    assert 0.0 <= xh < p.r0 and s.limit in ("pull-in", "saturation", "thermal runaway", "voltage limit",
                                            "coil face")
    xs, V = s.table(40)
    assert np.all(np.isfinite(V)) and np.all(V <= V_MAX * (1 + 1e-9)) and np.all(np.diff(V) > 0)
    if p.ksat > 0 and p.Rth == 0 and p.K5 == 0 and xh > 0:     # the plain Duffing spring: independent V(x)
        x = 0.5 * xh
        assert s.voltage_for(x) == pytest.approx(v_hold_indep(p, x, p.ksat), rel=2e-5)
    return s


@FAST
@given(p=diagnosed_models())
@example(p=ISSUE)
@example(p=DIAGNOSED)
def test_every_diagnosed_model_has_a_holdable_range(p):
    check_range(p)


@pytest.mark.deep
@DEEP
@given(p=diagnosed_models())
def test_deep_every_diagnosed_model_has_a_holdable_range(p):
    check_range(p)


def check_mpc(p):
    mpc = Mpc(p, MpcSettings(V_max_V=V_MAX))
    assert mpc.x_holdable == pytest.approx(Statics(p, V_max=V_MAX).x_holdable)
    V = mpc.command(0.0, np.full(mpc.s.horizon, 0.9 * p.r0), (0.0, 0.0, 0.0))   # a target beyond any range
    assert 0.0 <= V <= V_MAX


@FAST
@given(p=diagnosed_models())
@example(p=ISSUE)
@example(p=DIAGNOSED)
def test_the_mpc_initialises_for_every_diagnosed_model(p):
    check_mpc(p)


@pytest.mark.deep
@DEEP
@given(p=diagnosed_models())
def test_deep_the_mpc_initialises_for_every_diagnosed_model(p):
    check_mpc(p)


def controller_output(path, p, x_ref):
    """Initialise the controller FMU with the model p (feed-forward only, V_max = 30 V) and read V at x_ref."""
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = fmpy.extract(str(path))
    f = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="ctl")
    f.instantiate()
    try:
        f.setupExperiment(startTime=0.0)
        f.enterInitializationMode()
        values = {"Kp": 0.0, "Ki": 0.0, "V_max": V_MAX, **{k: float(getattr(p, k)) for k in
                                                            ("a", "r0", "D", "kB", "R", "L", "Em", "K1", "K2",
                                                             "C", "m", *(n for e in EFFECTS.values()
                                                                         for n in e.params))}}
        f.setReal([vr[k] for k in values], list(values.values()))
        f.exitInitializationMode()          # raises on fmi2Error
        f.setReal([vr["x_ref"], vr["x_meas"]], [x_ref, 0.0])
        V = f.getReal([vr["V"]])[0]
        f.terminate()
    finally:
        f.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)
    return V


def check_controller(path, p):
    s = Statics(p, V_max=V_MAX)
    V = controller_output(path, p, p.r0)                  # at the coil face: the range's end, at most V_max
    assert V == pytest.approx(s.v_pull_in if s.x_holdable > 0 else 0.0, rel=1e-6, abs=1e-9) and V <= V_MAX
    if s.x_holdable > 0 and p.Rth == 0 and p.K5 == 0:     # inside the range: the independent static inverse
        x = 0.5 * s.x_holdable
        assert controller_output(path, p, x) == pytest.approx(v_hold_indep(p, x, p.ksat), rel=2e-3)


@settings(FAST, max_examples=3, suppress_health_check=[HealthCheck.too_slow])
@given(p=diagnosed_models())
@example(p=ISSUE)
@example(p=DIAGNOSED)
def test_the_controller_fmu_initialises_for_every_diagnosed_model(controller_fmu_path, p):
    check_controller(controller_fmu_path, p)


@pytest.mark.deep
@settings(DEEP, max_examples=60)
@given(p=diagnosed_models())
def test_deep_the_controller_fmu_initialises_for_every_diagnosed_model(controller_fmu_path, p):
    check_controller(controller_fmu_path, p)
