"""fmu_src.specs (the bottom layer: pure Python) and the layers above it: imports only downward, the block
layout derived from the specs, and the whole-model functions of fmu_src.effects on arrays."""
import ast
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fmu_src import effects as fx
from fmu_src.model import FREE, ActuatorModel, EffectDynamics, block_head, state_names
from fmu_src.specs import (ALL_SPECS, BLOCK, EFFECT_FIELDS, EFFECTS, SPECS, TERM_FIELDS, Params, active_effects,
                           si_exponents, validate)
from fmu_src.terms import LAGS, TERMS

SRC = Path(__file__).resolve().parents[2] / "fmu_src"
# the layers, bottom up: a module may import only modules of lower layers
LAYERS = (("paramspec",), ("terms",), ("specs",), ("coil", "diaphragm", "field", "termsum"), ("effects",), ("integrator",), ("model",), ("statics",),
          ("slave_status",), ("mpc_actuator", "mpc_controller"), ("mpc_actuator_fmi3",))
ALL_ON = dict(Rth=8.0, tau_th=0.5, ksat=3.0, Kc=8.0, tau_c=0.3, K5=1e9, lam=0.3, tau_s=0.005)


def _fmu_src_imports(path: Path) -> set:
    """fmu_src modules a file imports (any import statement, also inside functions)."""
    mods = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            mods |= {a.name.split(".")[1] for a in node.names if a.name.startswith("fmu_src.")}
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0 and (node.module or "").split(".")[0] != "fmu_src":
                continue
            parts = node.module.split(".")[0 if node.level else 1:] if node.module else []
            mods |= set(parts[:1]) if parts else {a.name for a in node.names}
    return mods


def test_layers_import_only_downward():
    level = {m: i for i, layer in enumerate(LAYERS) for m in layer}
    for mod, i in level.items():
        for dep in _fmu_src_imports(SRC / f"{mod}.py"):
            assert dep in level, (mod, dep)
            assert level[dep] < i or (dep == mod), f"fmu_src.{mod} (layer {i}) imports fmu_src.{dep} (layer {level[dep]})"
    assert set(level) | {"__init__"} == {p.stem for p in SRC.glob("*.py")}


def test_specs_is_pure_python():
    """Importing the specs and validating parameters loads neither numpy, numba nor scipy."""
    code = ("import sys; from fmu_src.specs import Params, validate; Params(Rth=8.0, tau_th=1.0).validated(); "
            "print(sorted(m for m in ('numpy', 'numba', 'scipy') if m in sys.modules))")
    env = {k: v for k, v in os.environ.items()}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_params_fields_come_from_the_specs():
    names = [s.name for s in SPECS] + ["blocked"] + [s.name for e in EFFECTS.values() for s in e.param_specs]
    terms = [f"c_{t}" for t in TERMS] + [f"tau_{g}" for g in LAGS]      # then the term set's (fmu_src.terms)
    assert list(Params().as_dict()) == names + terms
    assert EFFECT_FIELDS == tuple(names[len(SPECS) + 1:]) and TERM_FIELDS == tuple(terms)
    p = Params()
    assert all(getattr(p, s.name) == s.default for s in ALL_SPECS) and p.blocked is False
    with pytest.raises(Exception):
        p.a = 1.0   # frozen
    assert p.with_(a=0.02).a == 0.02 and p.a == 0.015
    assert Params(Rth=8.0, tau_th=1.0).validated() == Params(Rth=8.0, tau_th=1.0)


@pytest.mark.parametrize("values,message", [
    ({"R": 0.0}, r"parameter R \[Ohm\] must be > 0, got 0.0"),
    ({"r0": -1e-3}, r"parameter r0 \[m\] must be >= 0"),
    ({"m": "heavy"}, r"parameter m must be a number"),
    ({"C": float("inf")}, r"parameter C must be finite"),
    ({"Rth": 8.0}, r"parameter tau_th \[s\] must be > 0 when Rth > 0 \(coil_heating on\), got 0.0"),
    ({"Kc": 3.0, "tau_c": 0.0}, r"parameter tau_c \[s\] must be > 0 when Kc > 0 \(viscoelastic_creep on\)"),
    ({"c_force_lag": -0.2}, r"parameter tau_F \[s\] must be > 0 when c_force_lag != 0 \(term force_lag on\), got 0.0"),
    ({"c_F_creep": 0.1, "tau_Fs": -1.0}, r"parameter tau_Fs \[s\] must be >= 0, got -1.0"),
    ({"c_quad_drag": float("nan")}, r"parameter c_quad_drag must be finite"),
])
def test_validate_names_the_parameter_and_rule(values, message):
    with pytest.raises(ValueError, match=message):
        validate(values)


def test_effect_rules_and_switches():
    validate({"tau_th": 0.0, "tau_c": 0.0})          # effects off: their time constants may be 0
    for name, e in EFFECTS.items():
        assert e.switch == e.params[0]
        assert active_effects(Params(**{e.switch: 1.0, **{n: 1.0 for n in e.positive_when_on}})) == (name,)


def test_si_exponents_of_unit_strings():
    # by hand: N = kg m s^-2, T = kg s^-2 A^-1, Ohm = V/A = kg m^2 s^-3 A^-2, H = Ohm s
    assert si_exponents("N.m/T2") == {"kg": -1, "m": 2, "s": 2, "A": 2}
    assert si_exponents("1/T2") == {"kg": -2, "s": 4, "A": 2}
    assert si_exponents("N/m5") == {"kg": 1, "m": -4, "s": -2}
    assert si_exponents("K/W") == {"kg": -1, "m": -2, "s": 3, "K": 1}
    assert si_exponents("H") == {"kg": 1, "m": 2, "s": -2, "A": -2}
    assert si_exponents("N.s/m") == {"kg": 1, "s": -1}
    assert si_exponents("1") == {}
    for bad in ("furlong", "m/", "", "N..m"):
        with pytest.raises(ValueError, match="unit"):
            si_exponents(bad)


def test_block_layout_is_derived_from_the_specs():
    idx = (list(BLOCK.param.values()) + list(BLOCK.switch.values()) + list(BLOCK.state.values()) + [BLOCK.terms]
           + list(BLOCK.lag_on.values()) + list(BLOCK.lag_state.values()))
    assert sorted(idx) == list(range(BLOCK.size))
    assert list(BLOCK.param) == [s.name for s in ALL_SPECS] and list(BLOCK.switch) == list(EFFECTS)
    assert list(BLOCK.state) == [s for e in EFFECTS.values() for s in e.states]
    assert list(BLOCK.lag_on) == list(LAGS) and list(BLOCK.lag_state) == [f"z_{g}" for g in LAGS]
    assert BLOCK.n_states_max == 3 + len(BLOCK.state) + len(LAGS)
    p = Params(r0=0.004, Kc=8.0, tau_c=0.3, tau_s=0.005)
    dyn = EffectDynamics(p)
    assert dyn.state_names == state_names(("viscoelastic_creep", "sensor_lag")) == ("I", "x", "v", "xc", "x_sensor",
                                                                                    "F_sensor")
    assert dyn.P[BLOCK.state["xc"]] == 3.0 and dyn.P[BLOCK.state["dT"]] == -1.0
    assert dyn.P[BLOCK.switch["sensor_lag"]] == 1.0 and dyn.P[BLOCK.switch["coil_heating"]] == 0.0
    assert dyn.P[BLOCK.param["tau_c"]] == 0.3 and dyn.P[BLOCK.param["r0"]] == 0.004
    with pytest.raises(ValueError, match="same effects"):
        block_head([Params(), Params(ksat=1.0)])
    with pytest.raises(ValueError, match="same effects"):
        block_head([Params(), Params(c_quad_drag=1.0)])
    # a term on: the term set's switch, every lag state after the effects' (here xc, x_sensor, F_sensor),
    # the lag switch of the lag in use only
    dyn = EffectDynamics(p.with_(c_F_creep=0.1, tau_Fs=0.2))
    assert dyn.state_names == ("I", "x", "v", "xc", "x_sensor", "F_sensor", "z_P", "z_F", "z_I", "z_Fs", "z_dahl")
    assert dyn.P[BLOCK.terms] == 1.0 and EffectDynamics(p).P[BLOCK.terms] == 0.0
    assert [dyn.P[BLOCK.lag_on[g]] for g in LAGS] == [0.0, 0.0, 0.0, 1.0, 0.0]
    assert [dyn.P[BLOCK.lag_state[z]] for z in ("z_P", "z_F", "z_I", "z_Fs")] == [6.0, 7.0, 8.0, 9.0]


def test_whole_model_functions_on_arrays_equal_the_compiled_scalar_model():
    """fmu_src.effects.rates / contact_force / stability_step on arrays of runs (parameters, states) equal the
    FMU's compiled right-hand side, contact force and step bound run by run."""
    rng = np.random.default_rng(3)
    n = 9
    ps = [Params(r0=rng.uniform(0.002, 0.006), K2=rng.uniform(20, 60), Em=rng.uniform(0.02, 0.06),
                 **{k: v * rng.uniform(0.5, 1.5) for k, v in ALL_ON.items()}) for _ in range(n)]
    P = block_head(ps)
    dyns = [EffectDynamics(p) for p in ps]
    ns = dyns[0].n_states
    Y = np.vstack([rng.uniform(0, 1, n), rng.uniform(-0.002, 0.0019, n), rng.uniform(-0.3, 0.3, n),
                   rng.uniform(0, 60, n), rng.uniform(-0.002, 0.002, n), rng.uniform(0, 0.002, n),
                   rng.uniform(0, 0.5, n)])
    V = rng.uniform(0, 15, n)
    G = np.array([d.kernel(float(p.r0 - x)) for d, p, x in zip(dyns, ps, Y[1])])
    F = fx.force(P, Y[0], G)
    out = np.empty((ns, n))
    fx.rates(P, Y, V, Y[1], Y[2], F, True, out)
    G0 = np.array([d.kernel.G0 for d in dyns])
    net = fx.contact_force(P, Y, fx.force(P, Y[0], G0))
    step = fx.stability_step(P, False)
    for i, d in enumerate(dyns):
        want = d.rhs(Y[:, i], V[i], FREE)
        assert out[:, i] == pytest.approx(want, rel=1e-13, abs=1e-12), i
        assert net[i] == pytest.approx(d.net_contact_force(Y[:, i]), rel=1e-13, abs=1e-15)
        assert step[i] == d.stability_step() == ActuatorModel(ps[i]).integ.max_step
