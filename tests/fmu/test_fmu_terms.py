"""The pythonfmu FMU carries the generic term set (fmu_src.terms): its parameters with units and descriptions,
fmpy validate clean, a step test with terms on reproducing the diagnosis's simulator (harness.sim) and the
Python model, and bad term values refused with fmi2Error and a message naming the parameter."""
from __future__ import annotations

import numpy as np
import pytest

from fmu_src.model import simulate
from fmu_src.specs import Params, si_exponents
from fmu_src.terms import LAGS, TERMS
from harness.sim import fmurun
from harness.sim.settings import Schedule
from harness.sim.simulator import PARAM_FIELDS, Runs, simulate as sim_simulate

ON = dict(c_quad_drag=3.0, c_even_spring=800.0, c_force_lag=0.2, tau_F=0.01, c_eddy_current=2.0, tau_I=0.005,
          c_x_quadratic=15.0, c_F_creep=0.1, tau_Fs=0.05, c_heat_softening=1.0, tau_P=0.2, c_dahl_friction=0.002,
          tau_dahl=2e-5)


def test_term_parameters_in_the_model_description(model_description):
    var = {v.name: v for v in model_description.modelVariables}
    units = {u.name: u for u in model_description.unitDefinitions}
    for t in TERMS.values():
        v = var[t.coef.name]
        assert v.causality == "parameter" and v.unit == t.unit and float(v.start) == 0.0
        assert t.basis in v.description and t.name in v.description
        bu = units[t.unit].baseUnit
        got = {k: getattr(bu, k) for k in ("kg", "m", "s", "A", "K") if getattr(bu, k)}
        assert got == si_exponents(t.unit), t.name
    for g in LAGS.values():
        v = var[f"tau_{g.name}"]
        assert v.unit == g.constant_unit and (g.constant_text or "time constant") in v.description
    assert var["tau_dahl"].unit == "m" and "presliding length" in var["tau_dahl"].description
    # by hand: N.s2/m2 = kg/m, N/m.W = kg m s^-2 / (m kg m^2 s^-3) = s/m^2
    assert si_exponents("N.s2/m2") == {"kg": 1, "m": -1} and si_exponents("N/m.W") == {"m": -2, "s": 1}


def test_fmpy_validate_is_clean(fmu_path):
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(fmu_path)) == []


@pytest.mark.parametrize("blocked", [False, True])
def test_fmu_with_terms_reproduces_the_diagnosis_simulator(fmu_path, blocked):
    """A step test with terms of every kind on: the FMU (through fmpy, its default rtol 1e-7) reproduces the
    Python model and the diagnosis's batched simulator (harness.sim, RK4 at 0.1 ms) to 1e-6 of the range."""
    p = Params(r0=0.005, blocked=blocked).with_(**ON)
    runs = Runs(params={k: np.array([getattr(p, k)]) for k in PARAM_FIELDS}, blocked=np.array([blocked]),
                V=np.array([10.0]), dt=1e-4)
    res = sim_simulate(runs, Schedule(t_end=0.3, fine_s=0.3))
    t = res.t
    V = np.full(t.size, 10.0)
    q = p.with_()
    fm = fmurun.run(q, t, V, fmu_path=fmu_path)
    fmu_p = fmurun.start_values(q)
    assert {k for k in ON} <= set(fmu_p)
    py = simulate(p, t, V)
    key, sim_y = ("F_sensor", res.F[0]) if blocked else ("x_sensor", res.x[0])
    for k in ("x", "F", "I", "x_sensor", "F_sensor"):
        assert np.max(np.abs(fm[k] - py[k])) <= 1e-6 * max(np.max(np.abs(py[k])), 1e-30), k
    assert np.max(np.abs(fm[key] - sim_y)) <= 1e-6 * np.max(np.abs(fm[key]))
    assert np.max(np.abs(fm["I"] - res.I[0])) <= 1e-6 * np.max(np.abs(fm["I"]))
    off = simulate(Params(r0=0.005, blocked=blocked), t, V)
    assert np.max(np.abs(off[key] - py[key])) > 1e-3 * np.max(np.abs(py[key]))     # the terms show


@pytest.mark.parametrize("values,message", [
    ({"c_force_lag": 0.3}, r"parameter tau_F \[s\] must be > 0 when c_force_lag != 0"),
    ({"c_quad_drag": -1.0}, r"parameter c_quad_drag \[N.s2/m2\] must be >= 0"),
    ({"c_even_spring": float("inf")}, r"parameter c_even_spring must be finite"),
    ({"c_F_creep": 0.1, "tau_Fs": -0.5}, r"parameter tau_Fs \[s\] must be >= 0"),
])
def test_bad_term_values_give_fmi2error(unzipdir, values, message):
    """The host survives: fmi2Error with the message, and a good run afterwards in the same process."""
    import re
    from fmpy import simulate_fmu
    from fmpy.fmi1 import FMICallException
    messages = []

    def logger(component, instance_name, status, category, msg):
        messages.append((status, (msg or b"").decode()))

    with pytest.raises(FMICallException) as exc:
        simulate_fmu(unzipdir, stop_time=0.01, output_interval=1e-3, start_values=values, logger=logger,
                     debug_logging=False)
    assert exc.value.status == 3
    assert any(st == 3 and re.search(message, m) for st, m in messages), messages
    good = simulate_fmu(unzipdir, stop_time=0.02, output_interval=1e-3, start_values={"c_quad_drag": 1.0})
    assert np.all(np.isfinite(good["x"]))
