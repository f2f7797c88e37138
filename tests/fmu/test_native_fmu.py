"""The native FMU (``build_fmu.py --native``: the model's equations traced from fmu_src into C, no Python) against
the pythonfmu FMU and the Python model it runs.

* model exchange (the same FMU; a state event for impact and release): integrated by fmpy's own solver (CVode)
  it agrees with the co-simulation within the solvers' tolerances, through contact and release;

* its modelDescription has the pythonfmu FMU's variables (names, value references, causality, variability,
  initial, descriptions, types, units, display units, start values), units, default experiment and model
  structure; fmpy validates it;
* on the default experiment and on random parameter / effect / input / contact cases (Hypothesis; fast profile
  here, ``-m deep`` for many more), its outputs equal the pythonfmu FMU's to 1e-9 relative (of each output's
  largest magnitude), and both refuse the same invalid parameter sets (fmi2Error);
* step for step: after every communication step its integrator arrays (front time, step size, mode, dense
  record, state rows) equal those of ``fmu_src.model.Integrator`` (to 1e-12), and its force-kernel table equals
  scipy's spline of ``fmu_src.field.ForceKernel``;
* the C host (tests/fmu/c_host) runs it with an empty environment (``env -i``), and the library links no
  libpython; fmu-manipulation-toolbox's checker accepts it.
"""
from __future__ import annotations

import ctypes
import math
import subprocess
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import build_fmu
from fmu_src import integrator as J
from fmu_src.model import ActuatorModel
from fmu_src.specs import EFFECTS, Params
from tests.fmu.native_helpers import EFFECT_VALUES as _EFFECT_VALUES
from tests.fmu.native_helpers import all_terms_on
from tests.fmu.native_helpers import (REALS, RTOL_OUT, TINY_OUT, Run, assert_same_outputs,
                                      assert_same_outputs_or_grazing_event)
from tests.fmu.native_helpers import python_accepts as _python_accepts
from tests.fmu.native_helpers import read_md as _md
from tests.fmu.native_helpers import row_ok as _row_ok

REPO = Path(__file__).resolve().parents[2]
HOST_SRC = REPO / "tests" / "fmu" / "c_host" / "fmi2_cs_host.c"


@pytest.fixture(scope="module")
def native_dir(native_fmu_path, tmp_path_factory) -> str:
    from fmpy import extract
    return extract(str(native_fmu_path), unzipdir=str(tmp_path_factory.mktemp("native_unzipped")))


# ------------------------------------------------------------------------------------------ modelDescription
def _variables(root):
    out = []
    for sv in root.find("ModelVariables").findall("ScalarVariable"):
        (typ,) = list(sv)
        out.append((dict(sv.attrib), typ.tag, dict(typ.attrib)))
    return out


def test_model_description_has_the_pythonfmu_fmus_variables(native_fmu_path, fmu_path):
    roots = [ET.fromstring(zipfile.ZipFile(p).read("modelDescription.xml")) for p in (native_fmu_path, fmu_path)]
    nat, py = roots
    nv, pv = _variables(nat), _variables(py)
    assert nv[:len(pv)] == pv
    # then the model-exchange states and their derivatives, locals with value references after the others
    extra = [v[0]["name"] for v in nv[len(pv):]]
    assert extra == [n for s in ("I", "x", "v", "dT", "xc", "x_sensor", "F_sensor", "z_P", "z_F", "z_I", "z_Fs",
                                 "z_dahl")
                     for n in (f"y.{s}", f"der(y.{s})")]
    assert all(v[0]["causality"] == "local" for v in nv[len(pv):])
    for tag in ("DefaultExperiment", "LogCategories", "ModelStructure/Outputs"):
        assert ET.tostring(nat.find(tag)) == ET.tostring(py.find(tag)), tag
    units = [[(u.get("name"), [(e.tag, e.attrib) for e in u])] for u in nat.find("UnitDefinitions")]
    assert units[:len(py.find("UnitDefinitions"))] == [[(u.get("name"), [(e.tag, e.attrib) for e in u])]
                                                       for u in py.find("UnitDefinitions")]
    assert nat.find("ModelExchange").get("modelIdentifier") == "mpc_actuator_native"
    assert nat.get("numberOfEventIndicators") == "1"
    for key in ("fmiVersion", "modelName", "description", "author", "variableNamingConvention"):
        assert nat.get(key) == py.get(key), key
    assert nat.get("guid") != py.get("guid")
    cs = nat.find("CoSimulation")
    assert cs.get("modelIdentifier") == "mpc_actuator_native" and cs.get("needsExecutionTool") == "false"
    assert [f.get("name") for f in cs.find("SourceFiles")] == ["mpc_native.c"]
    assert [f.get("name") for f in nat.find("ModelExchange/SourceFiles")] == ["mpc_native.c"]
    names = zipfile.ZipFile(native_fmu_path).namelist()
    assert {"sources/mpc_native.c", "sources/mpc_native_gen.h", "sources/mpc_native_vars.h",
            "binaries/linux64/mpc_actuator_native.so"} <= set(names)
    assert not [n for n in names if n.startswith("resources/") or n.endswith(".py")]


def test_fmpy_validates_it(native_fmu_path):
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(native_fmu_path)) == []
    _md(native_fmu_path)


def test_baked_start_values_are_the_pythonfmu_fmus(tmp_path):
    """--start-values: the same start values in both modelDescriptions, and the native FMU starts from them."""
    import json
    sv = tmp_path / "sv.json"
    sv.write_text(json.dumps({"r0": 0.004, "kB": 0.31, "Rth": 5.0, "tau_th": 2.0, "blocked": True}))
    from fmu_shim.native.package import slave_model_description, variables_header
    md, slave = slave_model_description(json.loads(sv.read_text()))
    files = {"mpc_native_vars.h": variables_header(md, slave, "{guid}")}
    root = ET.fromstring(md)
    starts = {s.get("name"): list(s)[0].get("start") for s in root.find("ModelVariables").findall("ScalarVariable")}
    assert starts["r0"] == "0.004" and starts["kB"] == "0.31" and starts["blocked"] == "true"
    # the slave's start voltage for the baked kB (pythonfmu writes starts with %.16g: in the C code the exact value)
    assert float(starts["V"]) == pytest.approx(0.23 / 0.31 * 15.0, rel=1e-15)
    assert f"#define START_V {0.23 / 0.31 * 15.0!r}" in files["mpc_native_vars.h"]
    assert "#define START_BLOCKED 1" in files["mpc_native_vars.h"]


# ------------------------------------------------------------------------------------------ outputs
def test_default_experiment_equals_the_pythonfmu_fmu(native_fmu_path, fmu_path):
    from fmpy import simulate_fmu
    res = [simulate_fmu(str(p), output=list(REALS) + ["contact"], output_interval=1e-3) for p in
           (native_fmu_path, fmu_path)]
    a, b = (np.column_stack([r[n].astype(float) for n in REALS + ("contact",)]) for r in res)
    assert len(a) == 1001
    assert_same_outputs(a, b, "default experiment")
    assert 0.7e-3 < a[-1, 0] < 0.8e-3   # settles near 0.741 mm (docs/fmu.md)



@st.composite
def cases(draw):
    """A parameter set (some out of range: both FMUs must refuse it alike), effects, blocked, and an input."""
    # gaps from 0.5 mm (or none) and some damping: with a gap of nanometres and no damping the dense output of the
    # impact step hugs the coil face (x - r0 at rounding level over much of the step), and where the event root
    # lands is decided by rounding (seen: r0 = 60 nm, C = 1e-7: from identical arrays the C root at 5 % of the
    # step, fmu_src's at its end)
    p = {"r0": draw(st.one_of(st.just(0.0), st.floats(0.0005, 0.012))), "a": draw(st.floats(0.008, 0.025)),
         "D": draw(st.floats(0.02, 0.07)),
         "Em": 0.0423 * draw(st.floats(0.3, 3.0)), "K1": draw(st.floats(0.0, 5e5)), "K2": draw(st.floats(10.0, 100.0)),
         "C": draw(st.floats(0.01, 1.0)), "m": draw(st.floats(0.001, 0.01)), "L": draw(st.floats(0.02, 0.3)),
         "rtol": draw(st.sampled_from([1e-7, 1e-9, 1e-5]))}
    for name in draw(st.sets(st.sampled_from(sorted(EFFECTS)))):
        scale = draw(st.floats(0.2, 2.0))
        p.update({k: v * scale for k, v in _EFFECT_VALUES[name].items()})
    if draw(st.booleans()) and "tau_th" in p:
        p["tau_th"] = 0.0   # Rth > 0 without its time constant: refused
    blocked = draw(st.booleans()) and draw(st.booleans())
    h = draw(st.sampled_from([1e-3, 2.5e-4, 4e-3]))
    levels = draw(st.lists(st.tuples(st.floats(0.0, 25.0, allow_subnormal=False), st.integers(1, 60)),
                           min_size=1, max_size=5))
    V = [v for v, n in levels for _ in range(n)]
    return p, blocked, h, V


def _check_case(native_dir, unzipdir, case):
    p, blocked, h, V = case
    runs = [Run(d, p, blocked) for d in (native_dir, unzipdir)]
    ok = [r.init() for r in runs]
    assert ok[0] == ok[1] == _python_accepts(p, blocked), (p, blocked, ok)
    if not ok[0]:
        for r in runs:
            r.close()
        return
    a, b = (r.simulate(V, h) for r in runs)
    for r in runs:
        r.close()
    assert_same_outputs_or_grazing_event(a, b, p.get("rtol", 1e-7), case)


_FAST = settings(max_examples=8, deadline=None, suppress_health_check=list(HealthCheck))


@_FAST
@given(case=cases())
def test_random_cases_equal_the_pythonfmu_fmu(native_dir, unzipdir, case):
    _check_case(native_dir, unzipdir, case)


@pytest.mark.deep
@settings(max_examples=300, deadline=None, suppress_health_check=list(HealthCheck))
@given(case=cases())
def test_random_cases_equal_the_pythonfmu_fmu_deep(native_dir, unzipdir, case):
    _check_case(native_dir, unzipdir, case)


def _c_statements(expr, target: str, known: dict) -> list[str]:
    """The C statements the native FMU's generated header holds for ``expr`` (``codegen.c_body``), as Python
    statements: the same operations in the same order (C and Python both evaluate a*b*c as (a*b)*c, pow is libm's
    pow in both)."""
    from fmu_shim.native.codegen import c_body
    lines = c_body([expr], [target], known).splitlines()
    return [line.strip().removeprefix("const double ").rstrip(";") for line in lines]


def _run_c(statements: list[str], target: str, **values) -> float:
    env = {"pow": math.pow, "sqrt": math.sqrt, **values}
    for st_ in statements:
        exec(st_, env)
    return env[target]


@pytest.mark.parametrize("V, output", [(1e-156, "F"), (float(np.finfo(float).tiny), "B")])
def test_subnormal_outputs_differ_by_the_operation_order(native_dir, unzipdir, V, output):
    """The shrunk case of a deep-profile failure (F off by 1.3e-9 relative, r0 = 0, coil heating; it reproduced only
    with Hypothesis's draw of a tiny voltage): a constant input of 1e-156 V makes F = Em*I^2*G about 1e-315 N, and
    one of 2.2e-308 V (the smallest normal double) makes B about 4e-310 T: subnormal numbers. Each FMU's output is
    bit for bit its own order of the same operations applied to its own I (and kernel value G(0)): the native FMU's
    the C statement generated from fmu_src (SymPy's order: G*pow(I, 2)*Em, I*pow(a, 3)*kB*pow(a^2 + r^2, -1.5)),
    the pythonfmu FMU's fmu_src's (Em*I*I*G, kB*I*a**3/(a*a + r*r)**1.5). In the subnormal range each rounding
    is to 4.9e-324 absolute, so the two orders differ by more than 1e-9 relative (the order alone: evaluated on the
    same I and G), while every difference is far below the smallest normal double (TINY_OUT)."""
    from fmu_src import effects as fx
    from fmu_src import field
    from fmu_src.specs import BLOCK
    from fmu_shim.native import codegen
    p = {"r0": 0.0, "Rth": 8.0, "tau_th": 0.5}
    runs = [Run(d, p) for d in (native_dir, unzipdir)]
    assert all(r.init() for r in runs)
    a, b = (r.simulate([V] * 20, 1e-3) for r in runs)
    S = np.zeros(J.NS)
    coef = np.zeros(4 * (field.ForceKernel.__init__.__defaults__[0] - 1))
    runs[0].fmu.dll.mpc_native_debug_arrays(ctypes.c_void_p(runs[0].fmu.component),
                                            S.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), None,
                                            coef.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
    for r in runs:
        r.close()
    model = ActuatorModel(Params(**p))
    P, G_py, G_nat = model.integ.S, float(model.integ.coef[3, 0]), float(coef.reshape(4, -1)[3, 0])
    assert np.array_equal(S[:BLOCK.size], P[:BLOCK.size])   # the same parameters (and effect switches)
    j, i_I = (REALS + ("contact",)).index(output), REALS.index("I")
    assert np.all(a[:, 0] == 0.0) and np.all(a[:, -1] == 1.0)   # in contact on the face (r0 = 0): r = 0
    scale = float(np.max(np.abs(b[:, j])))
    assert 0.0 < scale < TINY_OUT and 0.0 < np.max(np.abs(a[:, j])) < TINY_OUT   # subnormal on both sides
    known = {f"p_{n}": f"P[{i}]" for n, i in BLOCK.param.items()}
    if output == "F":
        mask = 1 << codegen.EFFECT_NAMES.index("coil_heating")
        c_code = _c_statements(fx.force(codegen.symbolic_block(mask), codegen.I_, codegen.G_), "F",
                               {**known, "I": "I", "G": "G"})
        native = [_run_c(c_code, "F", P=S, I=I, G=G_nat) for I in a[:, i_I]]
        python = [fx.force(P, I, G_py) for I in b[:, i_I]]
        same_inputs = [fx.force(P, I, G_nat) for I in a[:, i_I]]       # fmu_src's order on the native inputs
    else:
        pa, pkB = (codegen.param_symbol(n) for n in ("a", "kB"))
        c_code = _c_statements(field.axial_field(codegen.I_, codegen.R_, pa, pkB), "B",
                               {"p_a": "a", "p_kB": "kB", "I": "I", "r": "r"})
        av, kB = P[BLOCK.param["a"]], P[BLOCK.param["kB"]]
        native = [_run_c(c_code, "B", I=I, r=0.0, a=av, kB=kB) for I in a[:, i_I]]
        python = [field.axial_field(I, 0.0, av, kB) for I in b[:, i_I]]
        same_inputs = [field.axial_field(I, 0.0, av, kB) for I in a[:, i_I]]
    assert a[:, j].tolist() == native and b[:, j].tolist() == python, c_code   # bit for bit
    order_alone = float(np.max(np.abs(np.array(same_inputs) - a[:, j])))
    assert order_alone > RTOL_OUT * scale, (order_alone, scale)
    err = float(np.max(np.abs(a[:, j] - b[:, j])))
    assert RTOL_OUT * scale < err < 1e-6 * TINY_OUT, (err, scale)
    assert_same_outputs(a, b, (V, output))


# a deep-profile case (Hypothesis, no effects): after 152 steps of 4 ms the diaphragm comes to rest on the coil face
GRAZING_CASE = ({"r0": 0.0038698710301011945, "a": 0.010746552148132762, "D": 0.04211854624749282,
                 "Em": 0.05092543782746905, "K1": 290569.5974609745, "K2": 57.13120882216728, "C": 0.4402693650887131,
                 "m": 0.001, "L": 0.24781880359176703},
                0.004, [24.157402849083038] * 2 + [9.480570110717915] * 98 + [9.854073994633743e-223] * 42
                + [13.852873877363784] * 32)


def test_grazing_impact_is_decided_by_rounding(native_dir, unzipdir):
    """The shrunk deep-profile case of a grazing impact: the FMUs' outputs equal to RTOL_OUT up to the impact in
    the communication step 152, then part (the impact located at different times), by less than the tolerance.
    Replayed internal step by internal step (mpc_native_debug_set_step): from the same arrays fmu_src's step and
    the C step take the same decisions; from each one's own arrays (1e-12 apart after 152 steps) the impact lands
    at 64 % of the step in fmu_src and at the step's end in C."""
    p, h, V = GRAZING_CASE
    K = 152
    runs = [Run(d, p) for d in (native_dir, unzipdir)]
    assert all(r.init() for r in runs)
    a, b = (r.simulate(V, h) for r in runs)
    for r in runs:
        r.close()
    ok = _row_ok(a, b, RTOL_OUT)
    assert ok[:K + 1].all() and not ok.all() and a[K, -1] == b[K, -1] == 0.0 and a[K + 1, -1] == b[K + 1, -1] == 1.0
    with pytest.raises(AssertionError):
        assert_same_outputs(a, b, "grazing")
    assert_same_outputs_or_grazing_event(a, b, 1e-7, "grazing")
    # the internal steps of communication step K, on the same arrays and on each one's own
    model = ActuatorModel(Params(**p))
    model.reset(0.0)
    integ = model.integ
    n = integ.dyn.n_states
    run = Run(native_dir, p)
    assert run.init()
    run.simulate(V[:K], h)
    for k in range(K):
        model.advance(k * h + h, V[k])
    t_end = K * h + h
    ptr = lambda x: x.ctypes.data_as(ctypes.POINTER(ctypes.c_double))   # noqa: E731
    comp = ctypes.c_void_p(run.fmu.component)
    Sc, Wc, coef = np.zeros(J.NS), np.zeros(J.NW * n), np.zeros(integ.coef.size)
    run.fmu.dll.mpc_native_debug_arrays(comp, ptr(Sc), ptr(Wc), ptr(coef))
    assert np.max(np.abs(Wc.reshape(J.NW, n)[J.W_Y] - integ.W[J.W_Y]) / np.abs(integ.W[J.W_Y])) < 1e-10
    S, W = integ.S.copy(), integ.W.copy()
    impact = {}
    for side in ("same arrays", "own arrays"):
        Sp, Wp = S.copy(), W.copy()
        if side == "same arrays":
            Sc, Wc = S.copy(), np.ascontiguousarray(W).ravel().copy()
        while Sp[J.S_TF] < t_end:
            mode, start = Sp[J.S_MODE], (Sp.copy(), Wp.copy())
            # one internal step (integrator._step): advance to just past the front, the input held (no restart)
            assert J.advance(Sp, Wp, integ.coef, Sp[J.S_TF] + 1e-12, V[K]) == J.OK
            if side == "same arrays":   # the C step from fmu_src's arrays
                Sc, Wc = start[0].copy(), np.ascontiguousarray(start[1]).ravel().copy()
            run.fmu.dll.mpc_native_debug_set_step(comp, ptr(Sc), ptr(Wc), 1, ctypes.c_double(t_end))
            run.fmu.dll.mpc_native_debug_arrays(comp, ptr(Sc), ptr(Wc), None)
            if mode == J.FREE and Sp[J.S_MODE] == J.CONTACT:
                impact[side] = (Sp[J.S_DH], Sc[J.S_DH], Sc[J.S_MODE], Sp[J.S_TF] - Sp[J.S_DH])
                break
    run.close()
    dh_py, dh_c, mode_c, _ = impact["same arrays"]
    assert mode_c == J.CONTACT and dh_c == pytest.approx(dh_py, rel=1e-9)   # the same event, same place
    dh_py, dh_c, mode_c, t0 = impact["own arrays"]
    assert mode_c == J.CONTACT
    full = S[J.S_H]   # the steps before are free flight, both sides: compare the cut with the whole step
    assert dh_py < 0.7 * dh_c and dh_c > 0.99 * min(full, dh_c), (dh_py, dh_c)   # fmu_src cut the step, C did not


@pytest.mark.parametrize("p", [{"m": -1.0}, {"rtol": 1e-2}, {"r0": 2.0}, {"Rth": 1.0}, {"Em": 1e30},
                               {"tau_s": math.inf}, {"L": 1e-15},
                               # the generic term set: a term on without its lag's time constant, a dissipative
                               # term with a negative coefficient, a lag's time constant of 1 fs
                               {"c_force_lag": 0.2}, {"c_quad_drag": -1.0}, {"c_eddy_current": 1.0, "tau_I": 1e-15}])
def test_refuses_what_the_pythonfmu_fmu_refuses_and_recovers(native_dir, p):
    assert not _python_accepts(p, False) or "rtol" in p
    r = Run(native_dir, p)
    assert not r.init()
    r.close()
    r = Run(native_dir, p)
    from fmpy.fmi1 import FMICallException
    with pytest.raises(FMICallException):
        r.fmu.exitInitializationMode()
    r.fmu.reset()   # start values again: a normal run
    r.fmu.setupExperiment(startTime=0.0)
    r.fmu.enterInitializationMode()
    r.fmu.exitInitializationMode()
    out = r.simulate([11.9] * 5, 1e-3)
    r.close()
    assert out[-1, 3] > 0.0   # current rising


# ------------------------------------------------------------------------------------------ step for step
@pytest.mark.parametrize("params", [{"r0": 0.002}, {"r0": 0.003, **{k: v for d in _EFFECT_VALUES.values()
                                                                    for k, v in d.items()}},
                                    # every term of the generic term set on; Dahl's presliding length 20 mm: at a
                                    # realistic 50 um the stiff state makes the step sizes part by rounding after
                                    # 40 steps (1.1e-8 relative; the outputs agree to 1e-9: test_native_fmu_terms)
                                    {"r0": 0.002, **all_terms_on(0.002, presliding_m=0.02)}])
def test_integrator_arrays_equal_fmu_src_integrator_step_for_step(native_dir, params):
    """After every communication step (pull-in to contact, hold, release at V = 0, a new pull) the C integrator's
    arrays S (beyond the parameter block: view and front time, mode, held input, step size, dense record) and
    W (state, stages, dense rows, view) equal those of fmu_src.model.Integrator (modes and flags exactly, the
    numbers to 1e-8 relative), and its parameter block too (to 1e-12)."""
    model = ActuatorModel(Params(**params))
    model.reset(0.0)
    integ = model.integ
    n = integ.dyn.n_states
    S = np.zeros(J.NS)
    W = np.zeros(J.NW * n)
    coef = np.zeros(integ.coef.size)
    h = 1e-3
    V = [11.9] * 80 + [0.0] * 60 + [14.0] * 60
    seen = {"contact": 0, "release": 0}

    def compare(run, k):
        model.advance((k + 1) * h, V[k])
        got = run.fmu.dll.mpc_native_debug_arrays(
            ctypes.c_void_p(run.fmu.component), S.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
            W.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), coef.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        assert got == n
        np.testing.assert_allclose(S[:J.NP], integ.S[:J.NP], rtol=1e-12, atol=0)
        for i in (J.S_MODE, J.S_VMODE, J.S_DMODE, J.S_DENSE, J.S_K0, J.S_CHANGED):
            assert S[i] == integ.S[i], (k, i)
        # the step sizes follow from the error estimate, a difference of nearly equal stage sums: its rounding
        # (SymPy's order of operations, libm) moves them by ~1e-9 relative, the states far less
        np.testing.assert_allclose(S[J.NP:], integ.S[J.NP:], rtol=1e-8, atol=1e-300, err_msg=f"step {k}")
        Wp = integ.W
        scale = np.maximum(np.abs(Wp).max(axis=0), 1e-300)
        assert np.all(np.abs(W.reshape(J.NW, n) - Wp) <= 1e-8 * scale), (k, np.abs(W.reshape(J.NW, n) - Wp).max())
        seen["contact"] += integ.mode == J.CONTACT
        seen["release"] += k > 80 and integ.mode == J.FREE

    run = Run(native_dir, params)
    assert run.init()
    run.simulate(V, h, each=compare)
    run.close()
    assert seen["contact"] > 10 and seen["release"] > 10   # the events were exercised



def test_kernel_table_equals_scipys_spline(native_dir):
    """The C table (quadrature of the generated field functions + tridiagonal not-a-knot solve) against scipy's
    CubicSpline of fmu_src.field.force_kernel, piece by piece, for a few geometries."""
    for params in ({}, {"a": 0.01, "D": 0.06, "r0": 0.001, "kB": 0.4}, {"r0": 0.0}):
        model = ActuatorModel(Params(**params))
        run = Run(native_dir, params)
        assert run.init()
        coef = np.zeros(model.integ.coef.size)
        run.fmu.dll.mpc_native_debug_arrays(ctypes.c_void_p(run.fmu.component), None, None,
                                            coef.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        run.close()
        ref = model.integ.coef
        c = coef.reshape(ref.shape)
        # each row against its own magnitude: the values (c0) and slopes (c1) to 1e-12, higher terms looser
        for row, tol in ((3, 1e-12), (2, 1e-10), (1, 1e-7), (0, 1e-5)):
            assert np.max(np.abs(c[row] - ref[row])) <= tol * np.max(np.abs(ref[row])), (params, row)


# ------------------------------------------------------------------------------------------ no Python
@pytest.fixture(scope="module")
def c_host(tmp_path_factory) -> Path:
    cc = build_fmu.find_c_compiler()
    assert cc is not None, "no C compiler"
    exe = tmp_path_factory.mktemp("native_c_host") / "fmi2_cs_host"
    proc = subprocess.run([*cc, "-std=c11", "-O2", "-o", str(exe), str(HOST_SRC), "-ldl", "-lm"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return exe


def test_c_host_runs_it_with_an_empty_environment(c_host, native_dir, unzipdir):
    md = _md(native_dir)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outs = ("x", "I", "F")
    cmd = ["env", "-i", str(c_host), native_dir, "--step", "0.001", "--stop", "1", "--output",
           ",".join(str(vr[o]) for o in outs), "--instance", "A", "--input", f"{vr['V']}=11.9", f"{vr['r0']}=0.002",
           "--state-check", "300"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "state-check A: fresh instance: bit-identical outputs: ok" in proc.stderr
    header, *rows = proc.stdout.strip().splitlines()
    table = np.array([[float(v) for v in row.split(",")] for row in rows])
    run = Run(unzipdir, {"r0": 0.002})
    assert run.init()
    ref = run.simulate([11.9] * 1000, 1e-3)
    run.close()
    for j, o in enumerate(outs):
        col = ref[:, REALS.index(o)]
        assert np.max(np.abs(table[:, j + 1] - col)) <= RTOL_OUT * np.max(np.abs(col)), o
    ldd = subprocess.run(["ldd", str(Path(native_dir) / "binaries" / "linux64" / "mpc_actuator_native.so")],
                         capture_output=True, text=True)
    assert ldd.returncode == 0 and "python" not in ldd.stdout.lower(), ldd.stdout


def test_fmu_manipulation_toolbox_checker_accepts_it(native_fmu_path):
    import sys
    exe = Path(sys.executable).parent / "fmutool"
    assert exe.exists(), f"{exe} not found: install the test extra (fmu-manipulation-toolbox)"
    proc = subprocess.run([str(exe), "-input", str(native_fmu_path), "-check"], capture_output=True, text=True,
                          timeout=1200)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "This FMU seems to be compliant with FMI-2.0." in out, out
    assert "No semantic error against the FMI-2 standard." in out, out
    assert "ERROR" not in out, out


@pytest.mark.parametrize("test", ["T2", "T3", "T4", "T5", "T6", "T8"])
def test_cross_check_references_equal_the_pythonfmu_fmu(native_dir, unzipdir, test):
    """The cross-check cases of references/W20-D45 (parameters, input V sampled on the reference grid, held over
    each step): the native FMU's outputs equal the pythonfmu FMU's to 1e-9."""
    from dataclasses import asdict

    from harness.analysis.validation.crosscheck import load_reference_params, read_reference_csv
    ref_dir = REPO / "references" / "W20-D45"
    p = asdict(load_reference_params(ref_dir, test, None))
    blocked = p.pop("blocked")
    inp = read_reference_csv(ref_dir / f"{test}_in.csv")
    h = float(inp["time"][1] - inp["time"][0])
    V = inp["V"][:-1]
    runs = [Run(d, p, blocked) for d in (native_dir, unzipdir)]
    assert all(r.init() for r in runs)
    a, b = (r.simulate(V, h) for r in runs)
    for r in runs:
        r.close()
    assert_same_outputs(a, b, test)
    assert np.max(np.abs(b[:, 3])) > 0.1   # the current was driven


# ------------------------------------------------------------------------------------------ other platforms (slow)
ALL_PLATFORMS = "linux64,win64,darwin64,darwin-aarch64,linux-aarch64"


@pytest.mark.slow
def test_cross_compiled_binaries_export_fmi_and_win64_runs_under_wine(tmp_path, c_host):
    """build_fmu.py --native for every platform zig cc targets: each library exports every FMI 2.0 co-simulation
    function (the build checks it with llvm-readobj / llvm-nm; checked again here). Where Debian's wine64 is
    installed, the C host cross-compiled for win64 runs the win64 binary on the default-gap step with r0 = 2 mm
    (contact), and its numbers equal the linux64 binary's under the linux host to 1e-12."""
    import shutil
    import sys

    from fmpy import extract

    from build_fmu import FMI2_CS_FUNCTIONS
    from fmu_shim.native.package import TARGETS, exported_symbols
    out = tmp_path / "all.fmu"
    proc = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--native", ALL_PLATFORMS, "--out", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=3600)
    assert proc.returncode == 0, proc.stderr
    d = Path(extract(str(out), unzipdir=str(tmp_path / "x")))
    for plat in ALL_PLATFORMS.split(","):
        lib = d / "binaries" / plat / f"mpc_actuator_native{TARGETS[plat][1]}"
        assert lib.is_file(), plat
        assert set(FMI2_CS_FUNCTIONS) <= exported_symbols(lib, plat), plat
    wine = shutil.which("wine64") or shutil.which("wine") or ("/usr/lib/wine/wine64" if Path(
        "/usr/lib/wine/wine64").exists() else None)
    if wine is None:
        pytest.skip("wine64 not installed (apt-get install wine64): the win64 binary was built and checked only")
    exe = tmp_path / "host.exe"
    cc = subprocess.run([sys.executable, "-m", "ziglang", "cc", "-target", "x86_64-windows-gnu", "-std=c11", "-O2",
                         "-ffp-contract=off", "-o", str(exe), str(HOST_SRC)], capture_output=True, text=True,
                        timeout=1800)
    assert cc.returncode == 0, cc.stderr
    md = _md(d)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    args = ["--step", "0.001", "--stop", "1", "--output", f"{vr['x']},{vr['F']},{vr['I']}", "--instance", "A",
            "--input", f"{vr['V']}=11.9", f"{vr['r0']}=0.002"]
    env = {"WINEPREFIX": str(tmp_path / "wineprefix"), "WINEDEBUG": "-all", "HOME": str(tmp_path)}
    win = subprocess.run([wine, str(exe), "Z:" + str(d).replace("/", "\\"), *args], capture_output=True, text=True,
                         env=env, timeout=900)
    assert win.returncode == 0, win.stderr[-3000:]
    lin = subprocess.run(["env", "-i", str(c_host), str(d), *args], capture_output=True, text=True, timeout=300)
    assert lin.returncode == 0, lin.stderr[-3000:]
    a, b = ([[float(v) for v in row.split(",")] for row in p.stdout.strip().splitlines()[1:]] for p in (win, lin))
    a, b = np.array(a), np.array(b)
    assert a.shape == b.shape == (1001, 4)
    for j in range(1, 4):
        assert np.max(np.abs(a[:, j] - b[:, j])) <= 1e-12 * np.max(np.abs(b[:, j])), j
    assert b[-1, 1] == pytest.approx(0.002)   # in contact at the end


@pytest.mark.parametrize("params", [{}, {"r0": 0.002}, {"r0": 0.003, **{k: v for d in _EFFECT_VALUES.values()
                                                                      for k, v in d.items()}},
                                    {"blocked": True, "Rth": 8.0, "tau_th": 0.5}])
def test_model_exchange_under_fmpys_solver_agrees_with_co_simulation(native_fmu_path, params):
    """fmi_type='ModelExchange' (CVode, rtol 1e-8; the contact and release as state events) against the
    co-simulation (its DP5, rtol 1e-7) on a step on (impact) and off at 0.4 s (release), sampled on the same 1 ms
    grid (the event rows fmpy adds dropped): within 1e-5 of each output's largest magnitude."""
    from fmpy import simulate_fmu
    # a step off at 0.4 s (a repeated time: fmpy's model-exchange input interpolates linearly between samples)
    sig = np.array([(0.0, 11.9), (0.4, 11.9), (0.4, 0.0), (1.0, 0.0)], dtype=[("time", float), ("V", float)])
    outs = list(REALS) + ["contact"]
    kw = dict(output=outs, start_values=params, output_interval=1e-3, stop_time=1.0, input=sig)
    me = simulate_fmu(str(native_fmu_path), fmi_type="ModelExchange", relative_tolerance=1e-8, **kw)
    cs = simulate_fmu(str(native_fmu_path), fmi_type="CoSimulation", **kw)
    keep = np.r_[me["time"][1:] != me["time"][:-1], True]   # the last row at each time (after an event)
    me = me[keep]
    idx = np.searchsorted(me["time"], cs["time"] - 1e-12)
    assert np.all(np.abs(me["time"][idx] - cs["time"]) < 1e-9)
    me = me[idx]
    for o in REALS:
        a, b = me[o].astype(float), cs[o].astype(float)
        assert np.max(np.abs(a - b)) <= 1e-5 * max(np.max(np.abs(b)), 1e-12), o
    if params.get("r0"):   # contact and release happened, at the same samples but one or two around the events
        assert cs["contact"].any() and not cs["contact"][-1]
        assert np.sum(me["contact"] != cs["contact"]) <= 2
